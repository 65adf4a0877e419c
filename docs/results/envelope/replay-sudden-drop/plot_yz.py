"""Side view (height against distance north) of the re-flown Sudden-Drop configuration-1
flights, from trace_replay's per-flight CSVs in this directory, with the block and its
inflated underside as each body's map holds it. Run from this directory:

    ../../../../.venv/bin/python plot_yz.py
"""
import ft_sitl  # noqa: F401  (first: pins the BLAS settings before numpy loads)

# isort: split
import csv
from pathlib import Path

from matplotlib.figure import Figure
from matplotlib.patches import Rectangle

HERE = Path(__file__).resolve().parent
# sudden_drop-01-s0: one block, y 29.60-32.35 m, underside 1.5 m; ceiling 4 m
BLOCK_Y = (29.601, 32.351)
FLIGHTS = [  # (trace id, label, colour, inflation voxels of the body's map)
    ("d1b03d15", "EGO, 0.55 kg, TWR 3, 6 m/s²: climbs, swerves, collides", "tab:red", 2),
    ("6bfb7383", "EGO, 5.00 kg, TWR 3, 10 m/s²: dives, lags, collides", "tab:orange", 4),
    ("0155d1de", "PGO, 5.00 kg, TWR 3, 10 m/s²: swerves, collides", "tab:purple", 4),
    ("45a39c8f", "Fast-Planner, 5.00 kg, TWR 3, 10 m/s²: dives, succeeds", "tab:green", 4),
]


def load(tid):
    with open(HERE / f"{tid}.csv") as fh:
        rows = list(csv.DictReader(fh))
    return ([float(r["y_m"]) for r in rows], [float(r["z_m"]) for r in rows],
            [float(r["x_m"]) for r in rows])


fig = Figure(figsize=(10, 6.5), dpi=110)
ax, bx = fig.subplots(2, 1, sharex=True, gridspec_kw={"height_ratios": [3, 2]})
ax.add_patch(Rectangle((BLOCK_Y[0], 1.5), BLOCK_Y[1] - BLOCK_Y[0], 2.5, color="0.6",
                       label="block (full width, 1.5 m to above the ceiling)"))
for v, ls in ((2, ":"), (4, "--")):
    body = "0.55" if v == 2 else "5.00"
    ax.plot([BLOCK_Y[0] - 0.1 * v, BLOCK_Y[1] + 0.1 * v], [1.5 - 0.1 * v] * 2, color="0.3",
            ls=ls, lw=0.8, label=f"underside inflated by {v} voxels (the {body} kg map)")
ax.axhline(4.0, color="k", lw=0.8, label="ceiling (4 m)")
for tid, label, colour, _ in FLIGHTS:
    y, z, x = load(tid)
    ax.plot(y, z, color=colour, lw=1.2, label=label)
    bx.plot(y, x, color=colour, lw=1.2)
    ax.plot(y[-1], z[-1], "x", color=colour, ms=8)
ax.axvspan(BLOCK_Y[0] - 3.6, BLOCK_Y[0] - 3.2, color="tab:blue", alpha=0.08,
           label="the first reaction to the face (EGO, PGO: 3.2-3.6 m before it)")
ax.set_xlim(22, 40)
ax.set_ylim(0, 6.2)
ax.set_ylabel("height z (m)")
ax.set_yticks([0, 0.5, 1, 1.5, 2, 2.5, 3, 3.5, 4])
ax.legend(loc="upper left", fontsize=7, ncol=2)
bx.axvspan(*BLOCK_Y, color="0.85")
bx.set_ylabel("east x (m)\n(line at 25 m)")
bx.set_xlabel("north y (m): start 3 m, goal 47 m")
for a in (ax, bx):
    a.grid(alpha=0.3)
fig.suptitle("Sudden-Drop configuration 1, series-acc rows re-flown identical "
             "(x: where a flight ended)", fontsize=10)
fig.tight_layout()
fig.savefig(HERE / "side-view.png")
