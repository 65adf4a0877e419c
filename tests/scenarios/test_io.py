"""Scenario export (PLY, OBJ, DAE, PCD, SDF) and import from user spec files: round trips on
real generated scenarios, user meshes from other tools, and one clear error per bad input."""

from __future__ import annotations

import hashlib
import math
import xml.etree.ElementTree as ET
from pathlib import Path

import collada
import numpy as np
import pytest
import trimesh
from scipy.spatial import cKDTree

from ft_sitl.scenarios.families import build_scenario
from ft_sitl.scenarios.io import (
    EXPORT_FORMATS,
    MAX_PCD_POINTS,
    export_scenario,
    load_mesh,
    load_scenario,
    surface_points,
    write_scenario_spec,
)
from ft_sitl.scenarios.scenario import CATEGORIES, Scenario, ScenarioError

SCENARIOS = [("forest", 1), ("maze", 2)]


@pytest.fixture(scope="module")
def built() -> dict[str, Scenario]:
    return {f: build_scenario(f, i) for f, i in SCENARIOS}


@pytest.fixture(params=[f for f, _ in SCENARIOS])
def scenario(request, built) -> Scenario:
    return built[request.param]


def _files(d: Path) -> set[str]:
    return {p.name for p in d.iterdir()}


def _read_pcd(path: Path) -> tuple[dict[str, str], np.ndarray]:
    raw = path.read_bytes()
    header, pos = {}, 0
    while True:
        end = raw.index(b"\n", pos)
        line = raw[pos:end].decode("ascii")
        pos = end + 1
        if line.startswith("#"):
            continue
        key, _, value = line.partition(" ")
        header[key] = value
        if key == "DATA":
            break
    return header, np.frombuffer(raw[pos:], dtype="<f4").reshape(-1, 3)


def _same_surface(a: trimesh.Trimesh, b: trimesh.Trimesh, rel: float) -> None:
    scale = float(np.max(np.abs(a.bounds)))
    np.testing.assert_allclose(b.bounds, a.bounds, rtol=0, atol=rel * scale)
    assert math.isclose(b.area, a.area, rel_tol=rel)
    assert math.isclose(b.volume, a.volume, rel_tol=rel)


# ---- export ---------------------------------------------------------------------------------


def test_export_formats_are_the_documented_five():
    assert EXPORT_FORMATS == ("ply", "pcd", "obj", "dae", "sdf")
    assert "user" in CATEGORIES


@pytest.mark.parametrize("fmt", ["ply", "obj"])
def test_ply_and_obj_round_trip_bit_for_bit(scenario, fmt, tmp_path):
    written = export_scenario(scenario, tmp_path / f"s.{fmt}")
    assert written == [tmp_path / f"s.{fmt}"]
    assert _files(tmp_path) == {f"s.{fmt}"}  # nothing else written
    mesh = load_mesh(written[0])
    np.testing.assert_array_equal(mesh.vertices, scenario.mesh.vertices)
    np.testing.assert_array_equal(mesh.faces, scenario.mesh.faces)
    again = export_scenario(scenario, tmp_path / f"again.{fmt}")
    assert again[0].read_bytes() == written[0].read_bytes()  # reproducible bytes


def test_dae_is_z_up_metres_and_keeps_the_surface(scenario, tmp_path):
    (path,) = export_scenario(scenario, tmp_path / "s.dae")
    assert _files(tmp_path) == {"s.dae"}
    strict = collada.Collada(str(path), ignore=[])  # no broken references tolerated
    assert strict.assetInfo.upaxis == "Z_UP"
    assert strict.assetInfo.unitmeter == 1.0
    mesh = load_mesh(path)
    assert len(mesh.faces) == len(scenario.mesh.faces)
    _same_surface(scenario.mesh, mesh, rel=1e-6)  # pycollada reads float32
    assert export_scenario(scenario, tmp_path / "b.dae")[0].read_bytes() == path.read_bytes()


def test_pcd_points_lie_on_the_surface_and_cover_it(scenario, tmp_path):
    spacing = 0.5
    (path,) = export_scenario(scenario, tmp_path / "s.pcd", pcd_spacing_m=spacing)
    assert _files(tmp_path) == {"s.pcd"}
    header, pts = _read_pcd(path)
    assert path.read_bytes().startswith(b"# .PCD v0.7")
    assert header["VERSION"] == "0.7"
    assert header["FIELDS"] == "x y z"
    assert header["SIZE"] == "4 4 4" and header["TYPE"] == "F F F"
    assert header["COUNT"] == "1 1 1" and header["HEIGHT"] == "1"
    assert header["DATA"] == "binary"
    n = int(header["POINTS"])
    assert n == int(header["WIDTH"]) == len(pts) > 0
    assert 0.5 < n * spacing**2 / scenario.mesh.area < 1.5  # about one point per spacing^2
    _, dist, _ = trimesh.proximity.closest_point(scenario.mesh, pts.astype(float))
    assert dist.max() < 1e-4  # float32 rounding only
    # the cloud is surface_points as float32: at most one point per cell of the grid
    # aligned with the mesh bounds (cells from the float64 points: rounding crosses faces)
    exact = surface_points(scenario.mesh, spacing)
    np.testing.assert_array_equal(pts, exact.astype("<f4"))
    cells = np.floor((exact - scenario.mesh.bounds[0]) / spacing).astype(np.int64)
    assert len(np.unique(cells, axis=0)) == n
    # every part of the surface has a point within a cell diagonal
    probe, _ = trimesh.sample.sample_surface(scenario.mesh, 3000, seed=7)
    gap, _ = cKDTree(pts).query(probe)
    assert gap.max() <= math.sqrt(3) * spacing
    again = export_scenario(scenario, tmp_path / "b.pcd", pcd_spacing_m=spacing)
    assert again[0].read_bytes() == path.read_bytes()


def test_pcd_default_spacing_is_a_tenth_of_a_metre(built, tmp_path):
    s = built["forest"]
    (path,) = export_scenario(s, tmp_path / "f.pcd")
    header, pts = _read_pcd(path)
    np.testing.assert_array_equal(pts, surface_points(s.mesh, 0.1).astype("<f4"))
    assert 0.5 < len(pts) * 0.01 / s.mesh.area < 1.5


def test_sdf_world_references_the_dae_beside_it(scenario, tmp_path):
    written = export_scenario(scenario, tmp_path / "world.sdf")
    assert written == [tmp_path / "world.sdf", tmp_path / "world.dae"]
    assert _files(tmp_path) == {"world.sdf", "world.dae"}
    root = ET.parse(written[0]).getroot()
    assert root.tag == "sdf"
    major, minor = map(int, root.get("version").split("."))
    assert (major, minor) >= (1, 6)
    (world,) = root.findall("world")
    assert world.find("light[@name='sun']").get("type") == "directional"
    ground = world.find("model[@name='ground_plane']")
    assert ground.findtext("static") == "true"
    assert ground.find("link/collision/geometry/plane/normal").text == "0 0 1"
    obstacles = world.find("model[@name='obstacles']")
    assert obstacles.findtext("static") == "true"
    uris = [obstacles.findtext(f"link/{k}/geometry/mesh/uri") for k in ("collision", "visual")]
    assert uris[0] == uris[1] and uris[0].startswith("file:///")
    dae = Path(uris[0][len("file://"):])
    assert dae == written[1].resolve() and dae.is_file()
    _same_surface(scenario.mesh, load_mesh(dae), rel=1e-6)


def test_format_from_argument_and_suffix(built, tmp_path):
    s = built["maze"]
    assert export_scenario(s, tmp_path / "a", "PLY") == [tmp_path / "a.ply"]
    assert export_scenario(s, tmp_path / "b.OBJ") == [tmp_path / "b.OBJ"]
    assert export_scenario(s, tmp_path / "w", fmt="sdf") == [tmp_path / "w.sdf",
                                                             tmp_path / "w.dae"]


@pytest.mark.parametrize("name, fmt, words", [
    ("s.stl", None, ["'stl'", "ply, pcd, obj, dae, sdf"]),
    ("s", None, ["no file suffix", "ply, pcd, obj, dae, sdf"]),
    ("s.ply", "xyz", ["'xyz'", "ply, pcd, obj, dae, sdf"]),
    ("s.obj", "ply", [".obj", "'ply'"]),
    ("missing_dir/s.ply", None, ["missing_dir", "does not exist"]),
])
def test_bad_format_or_path_is_named(built, tmp_path, name, fmt, words):
    with pytest.raises(ScenarioError) as err:
        export_scenario(built["maze"], tmp_path / name, fmt)
    for w in words:
        assert w in str(err.value)
    assert _files(tmp_path) == set()


def test_a_directory_is_not_writable_as_a_file(built, tmp_path):
    (tmp_path / "d.ply").mkdir()
    with pytest.raises(ScenarioError, match="d.ply: cannot write: it is a directory"):
        export_scenario(built["maze"], tmp_path / "d.ply")


@pytest.mark.parametrize("spacing", [0, -0.1, float("nan"), "0.1", True])
def test_bad_pcd_spacing(built, tmp_path, spacing):
    with pytest.raises(ScenarioError, match="pcd_spacing_m"):
        export_scenario(built["maze"], tmp_path / "s.pcd", pcd_spacing_m=spacing)


def test_pcd_spacing_too_fine_is_refused_before_sampling(built, tmp_path):
    spacing = math.sqrt(built["maze"].mesh.area / MAX_PCD_POINTS) / 2
    with pytest.raises(ScenarioError, match="coarser spacing"):
        export_scenario(built["maze"], tmp_path / "s.pcd", pcd_spacing_m=spacing)


# ---- spec round trip --------------------------------------------------------------------


def _assert_same_setup(a: Scenario, b: Scenario) -> None:
    for key in ("start", "goal", "takeoff", "bounds_min", "bounds_max"):
        np.testing.assert_array_equal(getattr(b, key), getattr(a, key), err_msg=key)
    assert math.isclose(b.start_yaw, a.start_yaw, abs_tol=1e-12)
    assert b.goal_radius_m == a.goal_radius_m
    assert b.ceiling == a.ceiling


@pytest.mark.parametrize("suffix", [".toml", ".yaml", ".yml"])
def test_spec_round_trip(scenario, tmp_path, suffix):
    written = write_scenario_spec(scenario, tmp_path / f"spec{suffix}")
    assert written == [tmp_path / f"spec{suffix}", tmp_path / "spec.ply"]
    loaded = load_scenario(written[0])
    _assert_same_setup(scenario, loaded)
    assert loaded.mesh_digest() == scenario.mesh_digest()
    assert (loaded.family, loaded.index, loaded.seed, loaded.category) == (
        scenario.name, 1, 0, "user")
    prov = loaded.provenance
    assert prov["spec"] == str(written[0].resolve())
    assert prov["mesh"] == str(written[1].resolve())
    assert prov["mesh_sha256"] == hashlib.sha256(written[1].read_bytes()).hexdigest()
    # a user scenario keeps its family through another round
    again = write_scenario_spec(loaded, tmp_path / f"again{suffix}")
    assert load_scenario(again[0]).family == loaded.family


@pytest.mark.parametrize("fmt", ["obj", "dae", "ply"])
def test_spec_next_to_an_exported_mesh(built, tmp_path, fmt):
    s = built["maze"]
    (mesh_file,) = export_scenario(s, tmp_path / f"m.{fmt}")
    (tmp_path / "specs").mkdir()
    written = write_scenario_spec(s, tmp_path / "specs" / "m.toml", mesh_path=mesh_file)
    assert written == [tmp_path / "specs" / "m.toml"]
    assert f'mesh = "../m.{fmt}"' in written[0].read_text()
    loaded = load_scenario(written[0])
    _assert_same_setup(s, loaded)
    if fmt == "dae":
        _same_surface(s.mesh, loaded.mesh, rel=1e-6)
    else:
        assert loaded.mesh_digest() == s.mesh_digest()


def test_spec_needs_a_spec_suffix_and_an_existing_mesh(built, tmp_path):
    with pytest.raises(ScenarioError, match=r"s\.json: .*\*\.toml, \*\.yaml or \*\.yml"):
        write_scenario_spec(built["maze"], tmp_path / "s.json")
    with pytest.raises(ScenarioError, match="mesh_path: .*nope.ply is not an existing file"):
        write_scenario_spec(built["maze"], tmp_path / "s.toml", mesh_path=tmp_path / "nope.ply")
    with pytest.raises(ScenarioError, match=r"mesh_path: .*s\.pcd is not a mesh"):
        write_scenario_spec(built["maze"], tmp_path / "s.toml", mesh_path=tmp_path / "s.pcd")
    assert _files(tmp_path) == set()


# ---- user meshes ----------------------------------------------------------------------------


def _user_mesh() -> trimesh.Trimesh:
    """Two boxes: a 2 x 1 x 3 m pillar and a 6 x 0.5 x 2 m wall, in z-up metres."""
    a = trimesh.creation.box(extents=(2.0, 1.0, 3.0))
    a.apply_translation((5.0, 10.0, 1.5))
    b = trimesh.creation.box(extents=(6.0, 0.5, 2.0))
    b.apply_translation((8.0, 15.0, 1.0))
    return trimesh.util.concatenate([a, b])


Y_UP_FROM_Z_UP = np.array([[1, 0, 0, 0], [0, 0, 1, 0], [0, -1, 0, 0], [0, 0, 0, 1.0]])


def _write_user_mesh(tmp_path: Path, fmt: str) -> Path:
    mesh = _user_mesh()
    if fmt == "dae":  # trimesh (pycollada) labels every DAE it writes Y_UP: author it so
        mesh.apply_transform(Y_UP_FROM_Z_UP)
    path = tmp_path / f"yard.{fmt}"
    mesh.export(path)
    return path


USER_TOML = """\
name = "yard"
mesh = "{mesh}"
start = [5.0, 2.0, 1.5]
goal = [6.0, 22.0, 1.5]
ceiling = 4.0
goal_radius_m = 1.0
"""

USER_YAML = """\
mesh: {mesh}
start: [5.0, 2.0, 1.5]
goal: [6.0, 22.0, 1.5]
takeoff: [4.0, 1.0, 0]
bounds:
  min: [-5, -5, 0]
  max: [20, 30, 4]
start_yaw_deg: 45
"""


@pytest.mark.parametrize("fmt", ["stl", "obj", "ply", "dae"])
def test_user_mesh_with_toml_spec(tmp_path, fmt):
    mesh_path = _write_user_mesh(tmp_path, fmt)
    spec = tmp_path / "yard.toml"
    spec.write_text(USER_TOML.format(mesh=mesh_path.name))
    s = load_scenario(spec)
    _same_surface(_user_mesh(), s.mesh, rel=1e-6)
    assert (s.family, s.category, s.index, s.seed) == ("yard", "user", 1, 0)
    assert s.obstacle_count == 2
    np.testing.assert_array_equal(s.takeoff, [5.0, 2.0, 0.0])  # below start
    # default area: the mesh's xy extent grown to hold start and goal; ceiling from the key
    np.testing.assert_allclose(s.bounds_min, [4.0, 2.0, 0.0], atol=1e-6)
    np.testing.assert_allclose(s.bounds_max, [11.0, 22.0, 4.0], atol=1e-6)
    assert s.start_yaw == pytest.approx(math.atan2(20.0, 1.0))  # facing the goal
    assert s.goal_radius_m == 1.0


@pytest.mark.parametrize("fmt", ["stl", "obj", "ply", "dae"])
def test_user_mesh_with_yaml_spec(tmp_path, fmt):
    mesh_path = _write_user_mesh(tmp_path, fmt)
    (tmp_path / "specs").mkdir()
    spec = tmp_path / "specs" / "yard.yaml"
    spec.write_text(USER_YAML.format(mesh=f"../{mesh_path.name}"))
    s = load_scenario(spec)
    _same_surface(_user_mesh(), s.mesh, rel=1e-6)
    assert s.family == "user"
    np.testing.assert_array_equal(s.takeoff, [4.0, 1.0, 0.0])
    np.testing.assert_array_equal(s.bounds_min, [-5.0, -5.0, 0.0])
    np.testing.assert_array_equal(s.bounds_max, [20.0, 30.0, 4.0])
    assert s.start_yaw == pytest.approx(math.pi / 4)
    assert s.provenance["mesh"] == str(mesh_path.resolve())


def test_dae_units_are_applied(tmp_path):
    path = _write_user_mesh(tmp_path, "dae")
    text = path.read_text()
    assert "<up_axis>Y_UP</up_axis>" in text
    path.write_text(text.replace("<up_axis>", '<unit name="centimeter" meter="0.01"/><up_axis>'))
    mesh = load_mesh(path)
    expected = _user_mesh()
    expected.apply_scale(0.01)
    _same_surface(expected, mesh, rel=1e-6)


def test_obj_with_several_objects_becomes_one_mesh(tmp_path):
    path = tmp_path / "two.obj"
    path.write_text("o a\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"
                    "o b\nv 0 0 1\nv 1 0 1\nv 0 1 1\nf 4 5 6\n")
    mesh = load_mesh(path)
    assert len(mesh.faces) == 2
    np.testing.assert_array_equal(mesh.bounds, [[0, 0, 0], [1, 1, 1]])


# ---- bad spec files: the message names the file and the key --------------------------------


GOOD = {
    "mesh": '"yard.ply"',
    "start": "[5.0, 2.0, 1.5]",
    "goal": "[6.0, 22.0, 1.5]",
    "ceiling": "4.0",
}


def _spec(tmp_path: Path, suffix: str = ".toml", drop=(), **changes) -> Path:
    """A spec next to the user PLY, GOOD with keys dropped or changed (values as text)."""
    if not (tmp_path / "yard.ply").exists():
        _user_mesh().export(tmp_path / "yard.ply")
    values = {k: v for k, v in GOOD.items() if k not in drop}
    values.update(changes)
    sep = " = " if suffix == ".toml" else ": "
    path = tmp_path / f"spec{suffix}"
    path.write_text("".join(f"{k}{sep}{v}\n" for k, v in values.items()))
    return path


BAD_SPECS = [
    # (changes, drop, words the message must hold)
    ({"goall": "[1, 2, 3]"}, ("goal",), ["goall", "did you mean 'goal'"]),
    ({}, ("goal",), ["missing key(s) goal"]),
    ({}, ("mesh",), ["missing key(s) mesh"]),
    ({"start": '"north"'}, (), ["start", "3 numbers"]),
    ({"start": "[1.0, 2.0]"}, (), ["start", "3 numbers"]),
    ({"goal": '[1.0, "a", 2.0]'}, (), ["goal[1]", "must be a number"]),
    ({"goal": "[1.0, true, 2.0]"}, (), ["goal[1]", "must be a number"]),
    ({"ceiling": '"high"'}, (), ["ceiling", "must be a number"]),
    ({"ceiling": "inf"}, (), ["ceiling", "not a finite number"]),
    ({"start": "[nan, 2.0, 1.5]"}, (), ["start[0]", "not a finite number"]),
    ({"ceiling": "0"}, (), ["ceiling", "above the floor"]),
    ({"goal_radius_m": "-1"}, (), ["goal_radius_m", "positive"]),
    ({"start_yaw_deg": '"east"'}, (), ["start_yaw_deg", "must be a number"]),
    ({"name": '"my yard!"'}, (), ["name", "letters, digits"]),
    ({"name": "5"}, (), ["name", "5"]),
    ({"mesh": "3"}, (), ["mesh", "file path"]),
    ({"goal": "[6.0, 22.0, 9.0]"}, (), ["goal", "outside the bounds", "ceiling 4"]),
    ({"bounds_max": "[20.0, 20.0, 4.0]"}, ("ceiling",), ["goal", "outside the bounds"]),
    ({"start": "[5.0, 2.0, -0.5]"}, (), ["start", "below the floor"]),
    ({"goal": "[6.0, 22.0, -1.0]"}, (), ["goal", "below the floor"]),
    ({"takeoff": "[5.0, 2.0, 0.3]"}, (), ["takeoff", "on the floor"]),
    ({"bounds_min": "[0.0, 0.0, 1.0]"}, (), ["bounds_min", "z must be 0"]),
    ({"bounds_max": "[20.0, 30.0, 5.0]"}, (), ["ceiling", "disagrees", "bounds_max z"]),
    ({}, ("ceiling",), ["missing key 'ceiling'"]),
    ({"bounds": "{min = [0, 0, 0], max = [20, 30, 4]}", "bounds_min": "[0, 0, 0]"}, (),
     ["bounds", "not both"]),
    ({"bounds": "{min = [0, 0, 0], maks = [20, 30, 4]}"}, (),
     ["bounds", "maks", "did you mean 'max'"]),
    ({"bounds": "[0, 0, 0]"}, (), ["bounds", "must be a table"]),
    ({"bounds_min": "[30.0, 0.0, 0.0]", "bounds_max": "[20.0, 30.0, 4.0]"}, (),
     ["bounds", "must exceed"]),
]


@pytest.mark.parametrize("changes, drop, words", BAD_SPECS)
def test_bad_spec_names_file_and_key(tmp_path, changes, drop, words):
    path = _spec(tmp_path, drop=drop, **changes)
    with pytest.raises(ScenarioError) as err:
        load_scenario(path)
    msg = str(err.value)
    assert msg.startswith(f"{path}: "), msg
    for w in words:
        assert w in msg, msg


def test_yaml_non_finite_and_wrong_types(tmp_path):
    path = _spec(tmp_path, ".yaml", goal="[6.0, .nan, 1.5]", mesh="yard.ply")
    with pytest.raises(ScenarioError, match=r"spec\.yaml: goal\[1\]: nan is not a finite"):
        load_scenario(path)
    path = _spec(tmp_path, ".yaml", start="{x: 1}", mesh="yard.ply")
    with pytest.raises(ScenarioError, match=r"spec\.yaml: start: needs a list of 3 numbers"):
        load_scenario(path)


def test_syntax_errors_give_the_line(tmp_path):
    toml = tmp_path / "bad.toml"
    toml.write_text('mesh = "yard.ply"\nstart = [1, 2, 3\ngoal = [1, 2, 3]\n')
    with pytest.raises(ScenarioError, match=r"bad\.toml: not valid TOML: .*line 3"):
        load_scenario(toml)
    yml = tmp_path / "bad.yaml"
    yml.write_text("mesh: yard.ply\nstart: [1, 2, 3]\ngoal: [1, 2\nceiling: 3\n")
    with pytest.raises(ScenarioError, match=r"bad\.yaml: not valid YAML \(line \d+, column"):
        load_scenario(yml)


def test_spec_file_problems(tmp_path):
    with pytest.raises(ScenarioError, match=r"nope\.toml: no such spec file$"):
        load_scenario(tmp_path / "nope.toml")
    (tmp_path / "s.json").write_text("{}")
    with pytest.raises(ScenarioError, match=r"s\.json: unknown spec file type \.json"):
        load_scenario(tmp_path / "s.json")
    (tmp_path / "list.yaml").write_text("- 1\n- 2\n")
    with pytest.raises(ScenarioError, match=r"list\.yaml: the top level must be a table"):
        load_scenario(tmp_path / "list.yaml")
    (tmp_path / "empty.yaml").write_text("")
    with pytest.raises(ScenarioError, match=r"empty\.yaml: .* got nothing"):
        load_scenario(tmp_path / "empty.yaml")


BAD_MESHES = [
    # (file name, content or None for no file, words)
    ("gone.ply", None, ["gone.ply: mesh file not found"]),
    ("empty.stl", b"", ["empty.stl: the mesh file is empty"]),
    ("notes.txt", b"hello", ["notes.txt: not a mesh format (.txt)", ".ply, .obj, .stl, .dae"]),
    ("junk.ply", b"ply\nformat nonsense\n", ["junk.ply: cannot read it as PLY"]),
    ("lines.obj", b"v 0 0 0\nv 1 0 0\nl 1 2\n", ["lines.obj: holds no triangles"]),
    ("broken.dae", b"<COLLADA><asset>\n<up_axis>Z_UP</up_axis>\n", ["broken.dae: not valid XML",
                                                                     "line 3"]),
    ("sideways.dae", b"<COLLADA><asset><up_axis>W_UP</up_axis></asset></COLLADA>",
     ["sideways.dae: <up_axis>", "'W_UP'"]),
]


@pytest.mark.parametrize("name, content, words", BAD_MESHES)
def test_bad_mesh_files(tmp_path, name, content, words):
    if content is not None:
        (tmp_path / name).write_bytes(content)
    with pytest.raises(ScenarioError) as err:
        load_mesh(tmp_path / name)
    for w in words:
        assert w in str(err.value)
    spec = _spec(tmp_path, mesh=f'"{name}"')  # through a spec: file, key, then the mesh
    with pytest.raises(ScenarioError) as err:
        load_scenario(spec)
    assert str(err.value).startswith(f"{spec}: mesh: {tmp_path / name}: ")


def test_a_directory_is_not_a_mesh(tmp_path):
    (tmp_path / "d.ply").mkdir()
    with pytest.raises(ScenarioError, match=r"d\.ply: not a file"):
        load_mesh(tmp_path / "d.ply")
