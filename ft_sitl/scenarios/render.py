"""Pictures of a scenario in the style of the paper's Fig. 5: top view and perspective view.

:func:`render_scenario` draws a :class:`~ft_sitl.scenarios.scenario.Scenario` with

* the obstacles: in the top view their footprint (every triangle of the mesh projected on
  the floor, drawn lowest first, in a grey that darkens with height); in the perspective
  view the triangles themselves, in a grey that lightens with height and with Lambert
  shading from a fixed light;
* the area bounds (floor to flight ceiling) as a black outline;
* a green arrow at the start, pointing along ``start_yaw``;
* a red arrow ending at the goal, pointing along the start -> goal direction, and (top
  view) the circle of ``goal_radius_m`` around the goal;
* the straight start -> goal reference line in blue;
* optionally a flown trajectory, an ``(N, 3)`` array of ENU positions, as an orange curve
  drawn over the blue line (or any path: ``trajectory_label`` names it in the legend),
  and marked points, each a magenta ring with its label in the legend.

Every colour means one thing (the legend under the views names each); the title names the
scenario (:func:`scenario_title`), and the perspective view's z label reads upright.

Drawing uses matplotlib's Agg canvas directly (no ``pyplot``, no window, no global figure
registry), so it works headless and from worker processes. Most scenarios render in under
a second, a 130k-triangle mesh in about 1.5 s.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ft_sitl.scenarios.families import PAPER_NAMES

VIEWS = ("top", "perspective")
"""The views :func:`render_scenario` can draw, in the order they are usually shown."""

DEFAULT_DPI = 110
DPI_RANGE = (10, 1200)
MAX_FACES_3D = 150_000
"""The perspective view draws at most this many triangles (the largest ones)."""
MIN_HEIGHT_RATIO = 0.2
"""The perspective view stretches heights so the drawn height is at least this fraction
of the larger horizontal extent (flat scenes would otherwise be a sliver)."""

START_COLOR = "#00b400"
GOAL_COLOR = "#e00000"
LINE_COLOR = "#0046ff"
#: orange: not the goal's red nor the straight line's blue it is drawn over
TRAJECTORY_COLOR = "#ff8c00"
MARK_COLOR = "#d000d0"
BOUNDS_COLOR = "#202020"

_LIGHT = np.array([0.35, -0.75, 0.56])
_LIGHT = _LIGHT / np.linalg.norm(_LIGHT)
_VIEW_SIZE_IN = 6.4
"""Height of the figure (inches); each view gets a panel about this wide."""


def scenario_title(scenario) -> str:
    """The default title of a picture: ``"<name>: <paper family name>, <category>"``
    (e.g. ``"forest-01-s0: Forest, classic"``); a caller's own title should contain it."""
    return f"{scenario.name}: {_family_label(scenario)}"


def _family_label(scenario) -> str:
    prov = scenario.provenance
    paper = prov.get("paper_name") or PAPER_NAMES.get(scenario.family)
    if paper:
        return f"{paper}, {scenario.category}"
    spec = prov.get("spec")
    return f"{scenario.category} scenario" + (f" from {Path(spec).name}" if spec else "")


def _check_trajectory(trajectory) -> np.ndarray | None:
    if trajectory is None:
        return None
    try:
        traj = np.asarray(trajectory, dtype=float)
    except (TypeError, ValueError):
        raise ValueError("trajectory: needs an (N, 3) array of numbers") from None
    if traj.ndim != 2 or traj.shape[1] != 3:
        raise ValueError(f"trajectory: needs shape (N, 3) (x, y, z per row), got "
                         f"{traj.shape}")
    if len(traj) < 2:
        raise ValueError(f"trajectory: needs at least 2 points, got {len(traj)}")
    if not np.all(np.isfinite(traj)):
        bad = int(np.argmax(~np.all(np.isfinite(traj), axis=1)))
        raise ValueError(f"trajectory: row {bad} is not finite: {traj[bad].tolist()}")
    return traj


_AXIS_NAMES = {"x": ("x", "x_m"), "y": ("y", "y_m"), "z": ("z", "z_m")}


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _read_csv_trajectory(path: Path) -> np.ndarray:
    with open(path, newline="", encoding="utf-8") as fh:
        rows = [(n, [c.strip() for c in row]) for n, row in enumerate(csv.reader(fh), 1)
                if row and any(c.strip() for c in row) and not row[0].lstrip().startswith("#")]
    if not rows:
        raise ValueError(f"{path}: no rows")
    line, first = rows[0]
    if all(_is_number(c) for c in first):
        if len(first) != 3:
            raise ValueError(f"{path}: line {line} has {len(first)} columns; without a header "
                             "the file needs exactly 3 (x, y, z)")
        cols, names, body = [0, 1, 2], ["x", "y", "z"], rows
    else:
        header = [c.lower() for c in first]
        cols = []
        for axis, accepted in _AXIS_NAMES.items():
            found = [k for k, h in enumerate(header) if h in accepted]
            if not found:
                raise ValueError(f"{path}: the header (line {line}) has no {axis!r} column "
                                 f"(it has: {', '.join(first)})")
            cols.append(found[0])
        names, body = [first[k] for k in cols], rows[1:]
    out = np.empty((len(body), 3))
    for i, (line, row) in enumerate(body):
        for j, (k, name) in enumerate(zip(cols, names)):
            if k >= len(row):
                raise ValueError(f"{path}: line {line} has {len(row)} columns, no {name!r}")
            try:
                out[i, j] = float(row[k])
            except ValueError:
                raise ValueError(f"{path}: line {line}, column {name!r}: {row[k]!r} is not "
                                 "a number") from None
    return out


def load_trajectory(path) -> np.ndarray:
    """Read a trajectory, an ``(N, 3)`` array of ENU positions (m), from a file.

    ``.npy``: an array of shape ``(N, 3)``. ``.csv``: either exactly three numeric columns
    x, y, z, or a header row naming columns ``x``, ``y`` and ``z`` (or ``x_m``, ...; other
    columns such as ``t`` are ignored). Blank lines and lines starting with ``#`` are
    skipped. Raises ``ValueError`` naming the file (and line) for anything else.
    """
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"{path}: no such file")
    suffix = path.suffix.lower()
    if suffix == ".npy":
        try:
            data = np.load(path, allow_pickle=False)
        except (OSError, ValueError) as exc:
            raise ValueError(f"{path}: not a readable .npy array ({exc})") from None
    elif suffix == ".csv":
        try:
            data = _read_csv_trajectory(path)
        except UnicodeDecodeError:
            raise ValueError(f"{path}: not a text CSV file") from None
    else:
        raise ValueError(f"{path}: a trajectory file must end in .csv or .npy")
    try:
        return _check_trajectory(data)
    except ValueError as exc:
        raise ValueError(f"{path}: {str(exc).removeprefix('trajectory: ')}") from None


def _check_views(views) -> tuple[str, ...]:
    if isinstance(views, str):
        views = (views,)
    views = tuple(views)
    if not views:
        raise ValueError(f"views: give at least one of {', '.join(VIEWS)}")
    for v in views:
        if v not in VIEWS:
            raise ValueError(f"views: {v!r} is not one of {', '.join(VIEWS)}")
    if len(set(views)) != len(views):
        raise ValueError(f"views: {views} repeats a view")
    return views


def _check_marks(marks) -> list[tuple[np.ndarray, str]]:
    out = []
    for k, mark in enumerate(marks):
        try:
            point, label = mark
            point = np.asarray(point, dtype=float)
        except (TypeError, ValueError):
            raise ValueError(f"marks[{k}]: needs (point [x, y, z], label), got "
                             f"{mark!r}") from None
        if point.shape != (3,) or not np.all(np.isfinite(point)):
            raise ValueError(f"marks[{k}]: the point needs 3 finite numbers, got "
                             f"{point.tolist()}")
        out.append((point, str(label)))
    return out


def _goal_direction(scenario) -> np.ndarray:
    """Unit horizontal start -> goal direction (the start yaw when they coincide in xy)."""
    d = scenario.goal[:2] - scenario.start[:2]
    n = float(np.hypot(*d))
    if n < 1e-9:
        return np.array([math.cos(scenario.start_yaw), math.sin(scenario.start_yaw)])
    return d / n


def _arrow_length(scenario) -> float:
    return float(np.clip(0.08 * max(scenario.size[0], scenario.size[1]), 1.0, 8.0))


def _xy_limits(scenario, traj):
    lo, hi = scenario.bounds_min[:2].copy(), scenario.bounds_max[:2].copy()
    if traj is not None:
        lo = np.minimum(lo, traj[:, :2].min(axis=0))
        hi = np.maximum(hi, traj[:, :2].max(axis=0))
    pad = 0.04 * float(max(hi - lo))
    return lo - pad, hi + pad


def _greys(t: np.ndarray, at_floor: float, at_top: float) -> np.ndarray:
    """RGBA greys (slightly blue) for heights ``t`` in [0, 1], from grey level
    ``at_floor`` at 0 to ``at_top`` at 1."""
    g = at_floor + (at_top - at_floor) * np.clip(t, 0.0, 1.0)
    return np.column_stack([g, g, g * 0.97 + 0.03, np.ones_like(g)])


def _height_fraction(z: np.ndarray, scenario) -> np.ndarray:
    top = max(scenario.ceiling, float(z.max()) if len(z) else 0.0)
    return (z - scenario.floor) / max(top - scenario.floor, 1e-9)


def _draw_top(ax, scenario, traj, marks) -> None:
    # matplotlib: heavy, loaded only when plotting
    from matplotlib.collections import PolyCollection
    from matplotlib.patches import Circle, Rectangle

    tri = np.asarray(scenario.mesh.triangles, dtype=float).reshape(-1, 3, 3)
    xy = tri[:, :, :2]
    e1, e2 = xy[:, 1] - xy[:, 0], xy[:, 2] - xy[:, 0]
    keep = np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]) > 1e-10  # not vertical faces
    if keep.any():
        zmax = tri[keep, :, 2].max(axis=1)
        order = np.argsort(zmax, kind="stable")  # highest drawn last, on top
        colors = _greys(_height_fraction(zmax[order], scenario), at_floor=0.72, at_top=0.36)
        ax.add_collection(PolyCollection(xy[keep][order], facecolors=colors,
                                         edgecolors=colors, linewidths=0.25, zorder=1,
                                         antialiaseds=False))  # no seams
    lo, hi = scenario.bounds_min, scenario.bounds_max
    ax.add_patch(Rectangle(tuple(lo[:2]), hi[0] - lo[0], hi[1] - lo[1], fill=False,
                           edgecolor=BOUNDS_COLOR, linewidth=1.2, zorder=2))
    s, g = scenario.start, scenario.goal
    ax.plot([s[0], g[0]], [s[1], g[1]], color=LINE_COLOR, linewidth=1.8, zorder=3)
    if traj is not None:
        ax.plot(traj[:, 0], traj[:, 1], color=TRAJECTORY_COLOR, linewidth=1.6, zorder=4)
    for point, _ in marks:
        ax.plot(point[0], point[1], marker="o", markersize=11, markerfacecolor="none",
                markeredgecolor=MARK_COLOR, markeredgewidth=2.2, zorder=6)
    ax.add_patch(Circle(tuple(g[:2]), scenario.goal_radius_m, fill=False,
                        edgecolor=GOAL_COLOR, linestyle="--", linewidth=1.2, zorder=4))
    length = _arrow_length(scenario)
    yaw = np.array([math.cos(scenario.start_yaw), math.sin(scenario.start_yaw)])
    d = _goal_direction(scenario)
    style = dict(width=0.09 * length, head_width=0.32 * length, head_length=0.32 * length,
                 length_includes_head=True, zorder=5, linewidth=0)
    ax.arrow(s[0], s[1], *(length * yaw), color=START_COLOR, **style)
    tail = g[:2] - length * d
    ax.arrow(tail[0], tail[1], *(length * d), color=GOAL_COLOR, **style)
    (x0, y0), (x1, y1) = _xy_limits(scenario, traj)
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.set_aspect("equal")
    ax.set_xlabel("x (east) [m]")
    ax.set_ylabel("y (north) [m]")
    ax.set_title("top view", fontsize=10)


def _box_edges(lo, hi):
    """The 12 edges of the box lo..hi as pairs of 3-D points; the 4 of the top last."""
    c = np.array([[hi[i] if (k >> i) & 1 else lo[i] for i in range(3)] for k in range(8)])
    pairs = [(0, 1), (1, 3), (3, 2), (2, 0), (0, 4), (1, 5), (2, 6), (3, 7),
             (4, 5), (5, 7), (7, 6), (6, 4)]
    return [(c[a], c[b]) for a, b in pairs]


def _draw_perspective(ax, scenario, traj, marks, max_faces: int) -> None:
    # matplotlib: heavy, loaded only when plotting
    from matplotlib.ticker import MaxNLocator
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    tri = np.asarray(scenario.mesh.triangles, dtype=float).reshape(-1, 3, 3)
    zlo, zhi = scenario.floor, scenario.ceiling
    normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    area = np.linalg.norm(normals, axis=1)
    keep = np.flatnonzero(area > 1e-12)
    if len(keep) > max_faces:  # keep the largest: small faces leave small holes
        keep = np.sort(keep[np.argsort(-area[keep], kind="stable")[:max_faces]])
    tri, normals, area = tri[keep], normals[keep], area[keep]
    if len(tri):
        lambert = np.abs(normals @ _LIGHT) / area
        # the highest corner: both triangles of a wall's side get the same grey
        ztop = tri[:, :, 2].max(axis=1)
        colors = _greys(_height_fraction(ztop, scenario), at_floor=0.42, at_top=0.86)
        colors[:, :3] *= (0.4 + 0.6 * lambert)[:, None]
        ax.add_collection3d(Poly3DCollection(tri, facecolors=colors, edgecolors="none",
                                             linewidths=0, zorder=1))
        zlo = min(zlo, float(tri[:, :, 2].min()))
        zhi = max(zhi, float(tri[:, :, 2].max()))
    lo, hi = scenario.bounds_min, scenario.bounds_max
    for k, (a, b) in enumerate(_box_edges(lo, hi)):
        ax.plot(*np.column_stack([a, b]), color=BOUNDS_COLOR, linewidth=1.0,
                linestyle="--" if k >= 8 else "-", zorder=0.5)
    s, g = scenario.start, scenario.goal
    ax.plot(*np.column_stack([s, g]), color=LINE_COLOR, linewidth=1.8, zorder=3)
    if traj is not None:
        ax.plot(traj[:, 0], traj[:, 1], traj[:, 2], color=TRAJECTORY_COLOR, linewidth=1.6,
                zorder=4)
        zlo = min(zlo, float(traj[:, 2].min()))
        zhi = max(zhi, float(traj[:, 2].max()))
    for point, _ in marks:
        ax.plot([point[0]], [point[1]], [point[2]], marker="o", markersize=11,
                markerfacecolor="none", markeredgecolor=MARK_COLOR, markeredgewidth=2.2,
                zorder=6)
    length = _arrow_length(scenario)
    yaw = np.array([math.cos(scenario.start_yaw), math.sin(scenario.start_yaw), 0.0])
    d = np.append(_goal_direction(scenario), 0.0)
    tail = g - length * d
    for p, v, c in ((s, yaw, START_COLOR), (tail, d, GOAL_COLOR)):
        ax.quiver(*p, *(length * v), color=c, linewidth=2.6, arrow_length_ratio=0.35,
                  zorder=5)
    (x0, y0), (x1, y1) = _xy_limits(scenario, traj)
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.set_zlim(zlo, zhi)
    # equal scale on all axes, except that a flat scene's height is stretched to a
    # readable fraction of its width (the panel title says by how much)
    stretch = max(1.0, MIN_HEIGHT_RATIO * max(x1 - x0, y1 - y0) / (zhi - zlo))
    ax.set_box_aspect((x1 - x0, y1 - y0, stretch * (zhi - zlo)), zoom=1.1)
    ax.view_init(elev=38, azim=-115)
    ax.zaxis.set_major_locator(MaxNLocator(nbins=4))
    ax.set_xlabel("x (east) [m]")
    ax.set_ylabel("y (north) [m]")
    # upright, read bottom to top: mplot3d would turn it along the z axis's screen
    # direction, which from this view point reads upside down
    ax.zaxis.set_rotate_label(False)
    ax.set_zlabel("z (up) [m]", rotation=90)
    title = "perspective" if stretch == 1.0 else f"perspective (height x{stretch:.1f})"
    ax.set_title(title, fontsize=10)


def _legend(fig, traj, trajectory_label: str, marks) -> None:
    # matplotlib: heavy, loaded only when plotting
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    handles = [
        Line2D([], [], color=START_COLOR, linewidth=3, label="start (arrow: start yaw)"),
        Line2D([], [], color=GOAL_COLOR, linewidth=3, label="goal (dashed: goal radius)"),
        Line2D([], [], color=LINE_COLOR, linewidth=1.8, label="straight start-goal line"),
    ]
    if traj is not None:
        handles.append(Line2D([], [], color=TRAJECTORY_COLOR, linewidth=1.6,
                              label=trajectory_label))
    for _, label in marks:
        handles.append(Line2D([], [], linestyle="none", marker="o", markersize=8,
                              markerfacecolor="none", markeredgecolor=MARK_COLOR,
                              markeredgewidth=2, label=label))
    handles.append(Patch(facecolor="0.55", label="obstacles (darker: taller)"))
    fig.legend(handles=handles, loc="lower center", ncol=len(handles), fontsize=8,
               frameon=False)


def render_scenario(scenario, path=None, *, trajectory=None,
                    views: Sequence[str] = VIEWS, dpi: float = DEFAULT_DPI,
                    title: str | None = None, trajectory_label: str = "trajectory",
                    marks: Sequence[tuple[Sequence[float], str]] = ()):
    """Draw ``scenario`` (top and/or perspective view); save a PNG at ``path`` if given.

    ``trajectory`` is an optional ``(N, 3)`` array of ENU positions (m), drawn in
    :data:`TRAJECTORY_COLOR` and called ``trajectory_label`` in the legend. ``marks`` are
    ``(point, label)`` pairs: an ENU point (m) ringed in magenta, its label in the legend.
    ``views`` is a non-empty subset of :data:`VIEWS`, drawn left to right in that order.
    ``title`` replaces the default, :func:`scenario_title` (keep the scenario's name in
    it: ``f"{scenario_title(sc)} - ..."``).
    Returns the :class:`matplotlib.figure.Figure` (on an Agg canvas); the PNG is saved
    at ``dpi`` without tight cropping, so figure pixels and saved pixels coincide, with the
    title as its ``Title`` text.
    Raises ``ValueError`` for a bad trajectory, view or dpi.
    """
    # matplotlib: heavy, loaded only when plotting
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    traj = _check_trajectory(trajectory)
    views = _check_views(views)
    marks = _check_marks(marks)
    lo, hi = DPI_RANGE
    if not (isinstance(dpi, (int, float)) and math.isfinite(dpi) and lo <= dpi <= hi):
        raise ValueError(f"dpi: {dpi!r} must be a number within {lo}..{hi}")
    fig = Figure(figsize=(_VIEW_SIZE_IN * 1.05 * len(views), _VIEW_SIZE_IN), dpi=dpi)
    FigureCanvasAgg(fig)
    for k, view in enumerate(views):
        if view == "top":
            ax = fig.add_subplot(1, len(views), k + 1)
            _draw_top(ax, scenario, traj, marks)
        else:
            # annotations are drawn over the obstacles, as in the paper's figure, rather
            # than depth-sorted with them (mplot3d sorts whole artists, not pixels)
            ax = fig.add_subplot(1, len(views), k + 1, projection="3d",
                                 computed_zorder=False)
            _draw_perspective(ax, scenario, traj, marks, MAX_FACES_3D)
        ax.set_label(view)
    _legend(fig, traj, trajectory_label, marks)
    title = title if title is not None else scenario_title(scenario)
    fig.suptitle(title, fontsize=12)
    fig.subplots_adjust(left=0.06, right=0.97, bottom=0.12, top=0.9, wspace=0.15)
    if path is not None:   # the title in the PNG's Title text too, for a file browser
        fig.savefig(Path(path), dpi=dpi, format="png", metadata={"Title": title})
    return fig
