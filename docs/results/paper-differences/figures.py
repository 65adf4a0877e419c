"""Figures of this folder. Trajectories: `ft-sitl trial rerun docs/results/paper ID --trajectory /tmp/pd/NAME.csv` for the ids in README.md (NAME as used below)."""

import csv

import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt

from ft_sitl.scenarios.families import build_scenario
from ft_sitl.scenarios.solvability import convex_pieces
from perlin_rac_geometry import slice_grid  # this folder

OUT = str(__import__("pathlib").Path(__file__).resolve().parent) + "/"


def slice_occ(sc, z, step=0.1):
    cx, cy, lo, hi = slice_grid(sc, step)
    nx, ny = len(cx), len(cy)
    occ = np.zeros((nx, ny), bool)
    for p in convex_pieces(sc.mesh):
        if not (p.lo[2] <= z <= p.hi[2]):
            continue
        ix = np.flatnonzero((cx >= p.lo[0]) & (cx <= p.hi[0]))
        iy = np.flatnonzero((cy >= p.lo[1]) & (cy <= p.hi[1]))
        if not len(ix) or not len(iy):
            continue
        X = cx[ix][:, None]
        Y = cy[iy][None, :]
        inside = np.ones((len(ix), len(iy)), bool)
        for n, b in zip(p.normals, p.offsets):
            inside &= n[0] * X + n[1] * Y + n[2] * z <= b + 1e-9
        occ[ix[0] : ix[-1] + 1, iy[0] : iy[-1] + 1] |= inside
    return occ, lo, hi


def traj(name):
    r = list(csv.DictReader(open(f"/tmp/pd/{name}.csv")))
    return np.array([[float(a["t_s"]), float(a["x"]), float(a["y"]), float(a["z"])] for a in r])


def top(ax, sc, z, title, trajs=(), color="0.35"):
    zs = z if isinstance(z, (list, tuple)) else [z]
    occ = None
    for zz in zs:
        o, lo, hi = slice_occ(sc, zz)
        occ = o if occ is None else (occ | o)
    ax.imshow(
        occ.T,
        origin="lower",
        extent=(lo[0], hi[0], lo[1], hi[1]),
        cmap="Greys",
        vmin=0,
        vmax=1.6,
        interpolation="nearest",
    )
    ax.plot([sc.start[0], sc.goal[0]], [sc.start[1], sc.goal[1]], color="tab:blue", lw=0.8, ls="--")
    ax.add_patch(plt.Circle(sc.goal[:2], sc.goal_radius_m, fill=False, ec="tab:red", ls="--"))
    for name, lab, col in trajs:
        T = traj(name)
        ax.plot(T[:, 1], T[:, 2], color=col, lw=1.6, label=lab)
        ax.plot(T[-1, 1], T[-1, 2], marker="x", color=col, ms=9, mew=2)
    ax.set_title(title, fontsize=9)
    ax.set_aspect("equal")
    ax.set_xlabel("x east (m)")
    ax.set_ylabel("y north (m)")
    if trajs:
        ax.legend(fontsize=7, loc="lower right")


# 1. Perlin
fig, axs = plt.subplots(1, 4, figsize=(17, 6.2))
sc10 = build_scenario("perlin", 10, 0)
top(
    axs[0],
    sc10,
    2.0,
    "perlin-10 (ours: 0.05 per 0.25 m voxel = 0.2 cycles/m)\n0.98 kg platform, slice z = 2 m",
    [
        ("perlin10-ego", "EGO ae82e6b2: hovers 75 s, timeout", "tab:red"),
        ("perlin10-pgo", "PGO 5d19ab65: success", "tab:green"),
    ],
)
sc5 = build_scenario("perlin", 5, 0)
top(
    axs[1],
    sc5,
    2.0,
    "perlin-05 (ours), slice z = 2 m",
    [("perlin5-ego", "EGO 7dbe2030: never leaves the start", "tab:red")],
)
for ax, f in zip(axs[2:], [0.5, 1.0]):
    sc = build_scenario("perlin", 10, 0, params={"noise_frequency_per_voxel": f * 0.25})
    top(
        ax,
        sc,
        2.0,
        f"perlin-10 re-generated at {f} cycles/m\n(same fill rate 0.03; geometry only, not flown)",
    )
fig.suptitle(
    "Random Perlin-Noise: our fields vs the same generator at higher noise frequency (dark = obstacle at z = 2 m; x = end of flight)",
    fontsize=11,
)
fig.tight_layout()
fig.savefig(OUT + "perlin.png", dpi=90)
plt.close(fig)

# 2. Maze
fig, ax = plt.subplots(1, 1, figsize=(6.5, 8.5))
scm = build_scenario("maze", 2, 0)
top(
    ax,
    scm,
    1.0,
    "maze-02, 0.98kg-EGO Planner DIY, slice z = 1 m",
    [
        ("maze2-ego", "EGO 50a0974b: stops at y 16.8, gives up", "tab:red"),
        ("maze2-pgo", "PGO f067e57a: hits wall 29 at 1.6 m/s", "tab:orange"),
        ("maze2-fast", "Fast e0f36f96: backs out west, success", "tab:green"),
    ],
)
fig.tight_layout()
fig.savefig(OUT + "maze.png", dpi=90)
plt.close(fig)

# 3. Sudden-Drop: side view y-z and top view x-y for PGO
scs = build_scenario("sudden_drop", 4, 0)
blocks = scs.provenance["layout"]["blocks_y_m"]
fig, axs = plt.subplots(1, 2, figsize=(15, 5.5), gridspec_kw={"width_ratios": [1.6, 1]})
ax = axs[0]
for y0, y1 in blocks:
    ax.add_patch(plt.Rectangle((y0, 1.5), y1 - y0, 2.5, color="0.6"))
ax.axhline(4.0, color="k", lw=0.8)
ax.axhline(0, color="k", lw=0.8)
for name, lab, col in [
    ("sd4-pgo", "PGO 2d09eba5 (0.98 kg): out of bounds east", "tab:orange"),
    ("sd4-fast", "Fast e639aefe (1.50 kg): hits block 1 at 0.9 m/s", "tab:red"),
]:
    T = traj(name)
    ax.plot(T[:, 2], T[:, 3], color=col, label=lab, lw=1.4)
    ax.plot(T[-1, 2], T[-1, 3], "x", color=col, ms=9, mew=2)
ax.set_xlim(0, 50)
ax.set_ylim(-0.2, 4.3)
ax.set_xlabel("y north (m)")
ax.set_ylabel("z (m)")
ax.set_title(
    "sudden_drop-04: side view (grey: blocks from 1.5 m up, across the full width; ceiling 4 m)",
    fontsize=9,
)
ax.legend(fontsize=8, loc="upper left")
ax = axs[1]
for y0, y1 in blocks:
    ax.add_patch(plt.Rectangle((0, y0), 50, y1 - y0, color="0.75"))
T = traj("sd4-pgo")
sc_ = ax.scatter(T[::10, 1], T[::10, 2], c=T[::10, 3], s=4, cmap="viridis", vmin=0, vmax=4)
plt.colorbar(sc_, ax=ax, label="PGO altitude z (m)")
ax.set_xlim(0, 50)
ax.set_ylim(0, 50)
ax.set_aspect("equal")
ax.set_xlabel("x east (m)")
ax.set_ylabel("y north (m)")
ax.set_title("PGO 2d09eba5, top view coloured by altitude", fontsize=9)
fig.tight_layout()
fig.savefig(OUT + "sudden-drop.png", dpi=90)
plt.close(fig)

# 4. RAC
fig, ax = plt.subplots(1, 1, figsize=(6.5, 8.5))
scr = build_scenario("random_angle_cylinder", 10, 0)
top(
    ax,
    scr,
    [1.1, 1.3, 1.5, 1.7, 1.9],
    "random_angle_cylinder-10, 1.05kg-UAV 4\nobstacles anywhere in z 1.1-1.9 m (flight altitude 1.5 m)",
    [
        ("rac10-ego", "EGO bafb96c9: gives up 10 m from goal", "tab:red"),
        ("rac10-pgo", "PGO cd7b58f2: success", "tab:green"),
    ],
)
fig.tight_layout()
fig.savefig(OUT + "rac.png", dpi=90)
plt.close(fig)
print("ok")
