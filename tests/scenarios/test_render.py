"""Scenario pictures: real PNGs, checked pixel by pixel where the markers must be."""

import math

import numpy as np
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from PIL import Image

from ft_sitl.scenarios.families import build_scenario
from ft_sitl.scenarios.render import (
    GOAL_COLOR,
    LINE_COLOR,
    MARK_COLOR,
    START_COLOR,
    TRAJECTORY_COLOR,
    load_trajectory,
    render_scenario,
    scenario_title,
)

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def _rgb(color: str) -> np.ndarray:
    return np.array([int(color[k:k + 2], 16) for k in (1, 3, 5)], dtype=float)


def _near(img: np.ndarray, color: str, tol: float = 60.0) -> np.ndarray:
    """Mask of pixels within ``tol`` (RGB distance, 0..255 scale) of ``color``."""
    return np.linalg.norm(img - _rgb(color), axis=-1) < tol


def _pixel(fig, ax, x, y):
    """Row, column in the saved image of the data point (x, y) of the 2-D axes ``ax``."""
    px, py = ax.transData.transform((x, y))
    height = fig.canvas.get_width_height()[1]
    return int(round(height - py)), int(round(px))


def _window(img, rc, half=3):
    r, c = rc
    return img[r - half:r + half + 1, c - half:c + half + 1]


def _axes_region(fig, ax, img):
    bb = ax.get_window_extent()
    height = img.shape[0]
    return img[int(height - bb.y1):int(height - bb.y0), int(bb.x0):int(bb.x1)]


def _load(path) -> np.ndarray:
    with Image.open(path) as im:
        return np.asarray(im.convert("RGB"), dtype=float)


@pytest.fixture(scope="module")
def forest():
    return build_scenario("forest", 2, 0)


def _detour(sc) -> np.ndarray:
    """A trajectory from start to goal bulging 6 m east of the straight line."""
    s = np.linspace(0.0, 1.0, 80)
    pts = sc.start + s[:, None] * (sc.goal - sc.start)
    pts[:, 0] += 6.0 * np.sin(np.pi * s)
    return pts


def test_forest_with_trajectory_shows_start_goal_line_and_path(forest, tmp_path):
    path = tmp_path / "forest.png"
    traj = _detour(forest)
    fig = render_scenario(forest, path, trajectory=traj, dpi=100)
    assert isinstance(fig, Figure) and isinstance(fig.canvas, FigureCanvasAgg)
    data = path.read_bytes()
    assert data[:8] == PNG_MAGIC and 30_000 < len(data) < 3_000_000
    img = _load(path)
    w_in, h_in = fig.get_size_inches()
    assert img.shape[:2] == (round(h_in * 100), round(w_in * 100))

    top, persp = fig.axes[:2]
    assert (top.get_label(), persp.get_label()) == ("top", "perspective")
    assert fig._suptitle.get_text() == scenario_title(forest) == "forest-02-s0: Forest, classic"
    with Image.open(path) as im:   # the title in the file too
        assert im.info["Title"] == scenario_title(forest)
    assert top.get_xlabel().endswith("[m]") and top.get_ylabel().endswith("[m]")
    # the z label reads upright, bottom to top (mplot3d turned it to 274 deg: upside down)
    assert persp.zaxis.label.get_text() == "z (up) [m]"
    assert persp.zaxis.label.get_rotation() == 90

    # top view: green arrow just ahead of the start along start_yaw, red arrow just before
    # the goal, blue line half way, orange trajectory at its widest detour
    yaw = np.array([math.cos(forest.start_yaw), math.sin(forest.start_yaw)])
    p = forest.start[:2] + 1.0 * yaw
    assert _near(_window(img, _pixel(fig, top, *p)), START_COLOR).any()
    d = (forest.goal - forest.start)[:2]
    d /= np.linalg.norm(d)
    p = forest.goal[:2] - 1.5 * d
    assert _near(_window(img, _pixel(fig, top, *p)), GOAL_COLOR).any()
    mid = (forest.start + forest.goal)[:2] / 2
    assert _near(_window(img, _pixel(fig, top, *mid)), LINE_COLOR).any()
    at_detour = _window(img, _pixel(fig, top, *traj[40, :2]))
    assert _near(at_detour, TRAJECTORY_COLOR).any() and not _near(at_detour, GOAL_COLOR).any()
    # ... and none of those colours where nothing is drawn (the area's empty corner)
    corner = _window(img, _pixel(fig, top, forest.bounds_max[0] - 0.3, 0.3), half=1)
    assert not (_near(corner, START_COLOR) | _near(corner, GOAL_COLOR)).any()

    # perspective view: all three markers and the trajectory appear inside its axes
    region = _axes_region(fig, persp, img)
    for color in (START_COLOR, GOAL_COLOR, LINE_COLOR, TRAJECTORY_COLOR):
        assert _near(region, color).sum() > 20, color
    # the legend names each colour once
    legend = {t.get_text(): h.get_color() for t, h in
              zip(fig.legends[0].get_texts(), fig.legends[0].legend_handles, strict=True)
              if hasattr(h, "get_color")}
    assert legend["trajectory"] == TRAJECTORY_COLOR
    assert legend["straight start-goal line"] == LINE_COLOR


def test_every_marker_has_a_colour_of_its_own():
    """The trajectory was drawn in the goal's red: each colour must be told from every
    other at the pixel tests' tolerance."""
    colours = [START_COLOR, GOAL_COLOR, LINE_COLOR, TRAJECTORY_COLOR, MARK_COLOR]
    for i, a in enumerate(colours):
        for b in colours[i + 1:]:
            assert np.linalg.norm(_rgb(a) - _rgb(b)) > 120, (a, b)


def test_marks_and_the_path_label(forest, tmp_path):
    path = tmp_path / "marked.png"
    point = (30.0, 20.0, 1.5)  # a clear spot east of the line
    fig = render_scenario(forest, path, trajectory=_detour(forest), dpi=100,
                          trajectory_label="shortest path", marks=[(point, "narrowest")])
    labels = [t.get_text() for t in fig.legends[0].get_texts()]
    assert "shortest path" in labels and "narrowest" in labels and "trajectory" not in labels
    img = _load(path)
    top, persp = fig.axes[:2]
    ring = _window(img, _pixel(fig, top, *point[:2]), half=8)
    assert _near(ring, MARK_COLOR).sum() > 10
    assert _near(_axes_region(fig, persp, img), MARK_COLOR).sum() > 10
    without = tmp_path / "plain.png"
    render_scenario(forest, without, dpi=100)
    assert not _near(_load(without), MARK_COLOR).any()
    for bad, message in [([((1.0, 2.0), "x")], r"marks\[0\]: the point needs 3 finite"),
                         ([(1.0, 2.0, 3.0)], r"marks\[0\]: needs \(point"),
                         ([((0.0, np.nan, 1.0), "x")], "3 finite numbers")]:
        with pytest.raises(ValueError, match=message):
            render_scenario(forest, marks=bad)


def test_top_view_fills_obstacle_footprints(tmp_path):
    sc = build_scenario("sudden_drop", 1, 0)  # one block across the whole area
    path = tmp_path / "drop.png"
    fig = render_scenario(sc, path, views=("top",), dpi=100)
    assert len(fig.axes) == 1 and fig.axes[0].get_label() == "top"
    img = _load(path)
    (x0, y0, _), (x1, y1, _) = sc.mesh.bounds
    assert y1 - y0 >= 1.5
    for x in (x0 + 2, x0 + 10, x1 - 10, x1 - 2):  # away from the line at the centre
        v = img[_pixel(fig, fig.axes[0], x, (y0 + y1) / 2)]
        assert v.max() < 215 and v.max() - v.min() < 20, (x, v)  # grey, not white
    v = img[_pixel(fig, fig.axes[0], x0 + 5, y1 + 3)]
    assert v.min() > 245  # open floor stays white


@pytest.mark.slow
def test_largest_family_renders(tmp_path):
    # (how long it takes is measured in bench/bench_scenarios.py, not asserted here)
    sc = build_scenario("perlin", 1, 0)
    assert len(sc.mesh.faces) > 30_000
    path = tmp_path / "perlin.png"
    fig = render_scenario(sc, path, title="my title")
    assert fig._suptitle.get_text() == "my title"
    img = _load(path)
    for ax in fig.axes:  # the obstacles cover a good share of both views in grey
        region = _axes_region(fig, ax, img)
        grey = (region.max(axis=-1) - region.min(axis=-1) < 12) & (region.max(axis=-1) < 215)
        assert grey.mean() > 0.08, ax.get_label()
    assert path.stat().st_size > 30_000


def test_bad_arguments_raise_value_errors_naming_them(forest):
    with pytest.raises(ValueError, match=r"trajectory: needs shape \(N, 3\)"):
        render_scenario(forest, trajectory=np.zeros((5, 2)))
    with pytest.raises(ValueError, match="at least 2 points"):
        render_scenario(forest, trajectory=np.zeros((1, 3)))
    with pytest.raises(ValueError, match="row 1 is not finite"):
        render_scenario(forest, trajectory=[[0, 0, 0], [1, np.nan, 0]])
    with pytest.raises(ValueError, match="'side' is not one of top, perspective"):
        render_scenario(forest, views=("top", "side"))
    with pytest.raises(ValueError, match="dpi"):
        render_scenario(forest, dpi=0)


def test_load_trajectory_csv_and_npy(tmp_path):
    ref = np.array([[1.0, 2.0, 3.0], [4.0, 5.0, 6.5]])
    plain = tmp_path / "plain.csv"
    plain.write_text("# x, y, z\n1,2,3\n\n4, 5, 6.5\n")
    np.testing.assert_array_equal(load_trajectory(plain), ref)
    header = tmp_path / "header.csv"
    header.write_text("t,Z,y,x,speed\n0,3,2,1,0\n0.1,6.5,5,4,1\n")
    np.testing.assert_array_equal(load_trajectory(header), ref)
    npy = tmp_path / "traj.npy"
    np.save(npy, ref)
    np.testing.assert_array_equal(load_trajectory(npy), ref)


@pytest.mark.parametrize("name, text, message", [
    ("bad.csv", "x,y,z\n1,2,3\n4,five,6\n", r"line 3, column 'y': 'five' is not a number"),
    ("noz.csv", "t,x,y\n0,1,2\n", r"has no 'z' column \(it has: t, x, y\)"),
    ("four.csv", "1,2,3,4\n5,6,7,8\n", "line 1 has 4 columns"),
    ("short.csv", "x,y,z\n1,2\n", "line 2 has 2 columns, no 'z'"),
    ("one.csv", "1,2,3\n", "at least 2 points"),
    ("empty.csv", "\n# nothing\n", "no rows"),
    ("traj.txt", "1,2,3\n", "must end in .csv or .npy"),
])
def test_load_trajectory_errors_name_file_and_line(tmp_path, name, text, message):
    f = tmp_path / name
    f.write_text(text)
    with pytest.raises(ValueError, match=message) as info:
        load_trajectory(f)
    assert str(f) in str(info.value)


def test_load_trajectory_npy_errors(tmp_path):
    f = tmp_path / "flat.npy"
    np.save(f, np.zeros(6))
    with pytest.raises(ValueError, match=r"shape \(N, 3\)"):
        load_trajectory(f)
    g = tmp_path / "junk.npy"
    g.write_bytes(b"not numpy")
    with pytest.raises(ValueError, match="not a readable .npy"):
        load_trajectory(g)
    with pytest.raises(ValueError, match="no such file"):
        load_trajectory(tmp_path / "missing.npy")
