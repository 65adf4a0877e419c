"""Scenario export (PLY, PCD, OBJ, DAE, Gazebo SDF) and import from a user spec file.

Export
------
``export_scenario(scenario, path, fmt)`` writes the obstacle mesh of a scenario (ENU
metres, z up; no floor, no ceiling) in one of :data:`EXPORT_FORMATS`:

* ``ply``: binary little-endian PLY, vertices as ``double`` so the mesh comes back bit for
  bit (:meth:`Scenario.mesh_digest` is unchanged by a PLY round trip);
* ``obj``: Wavefront OBJ, coordinates printed as Python's shortest exact ``repr`` (exact
  too);
* ``dae``: COLLADA 1.4.1 with ``<up_axis>Z_UP</up_axis>`` and ``<unit meter="1"/>`` (so
  Gazebo does not turn the world on its side), one grey material and per-face normals
  (flat shading of the boxes and prisms); the text is exact but pycollada (and so trimesh
  and :func:`load_mesh`) reads it back as float32;
* ``pcd``: a PCL point cloud (PCD v0.7, ``FIELDS x y z``, float32, ``DATA binary``) of
  points on the obstacle surfaces, at most one per cubic cell of side ``pcd_spacing_m``
  (see :func:`surface_points`); deterministic;
* ``sdf``: a Gazebo SDF 1.6 world (ground plane, sun, one static model whose visual and
  collision geometry is the DAE written beside it, same stem, referred to by a ``file://``
  absolute URI: the one form both Gazebo Classic and Gazebo Sim resolve).

The files are byte-for-byte reproducible: the same scenario gives the same bytes.

Import
------
``load_scenario(spec)`` reads a TOML (``.toml``) or YAML (``.yaml``/``.yml``) spec::

    name = "my_yard"                 # optional; becomes the scenario family (default "user")
    mesh = "yard.stl"                # PLY, OBJ, STL or DAE; relative to the spec file
    start = [2.0, 3.0, 1.5]          # ENU metres; the run starts here
    goal = [30.0, 40.0, 1.5]
    takeoff = [2.0, 3.0, 0.0]        # optional; default: below start, on the floor
    ceiling = 6.0                    # flight ceiling (m) = bounds_max z
    bounds_min = [0.0, 0.0, 0.0]     # optional, or: bounds = {min = [..], max = [..]}
    bounds_max = [40.0, 50.0, 6.0]   # optional (then ceiling is required)
    start_yaw_deg = 90.0             # optional; default: facing the goal
    goal_radius_m = 2.0              # optional

    [movers]                         # optional moving obstacles, placed for seed 0
    count = 4                        # (scenarios.movers.SCHEMA: count or density, speed,
    speed_m_s = 1.2                  #  shape, path, sizes ...)

    # ... or each mover given (scenarios.movers.movers_from_list), as an array of tables:
    [[movers]]
    shape = "person"
    radius_m = 0.3
    height_m = 1.8
    points = [[10.0, 4.0], [10.0, 20.0]]   # the centre's path, walked back and forth
    speed_m_s = 1.5

Without bounds, the area is the mesh's xy extent grown to hold takeoff, start and goal,
with no margin: give bounds when start or goal lie outside the obstacles' extent. The
floor is z = 0. The movers' clock starts at simulation time 0 (a trial restarts it when
navigation starts). Every problem raises :class:`ScenarioError` naming the file and the
key.

On a command line a scenario is :func:`scenario_from_spec`: ``FAMILY:INDEX[:SEED]`` or a
spec file, either followed by ``+dynamic(KEY=VALUE, ...)`` to add movers placed for the
scenario's seed (``forest:3+dynamic(count=8, speed=1.5)``).
:func:`write_scenario_spec` writes such a spec for a scenario, so that export and import
round-trip.
"""

from __future__ import annotations

import dataclasses
import hashlib
import itertools
import json
import math
import os
import re
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import trimesh

from ft_sitl import __version__
from ft_sitl.config import SUFFIXES, Table, read_document
from ft_sitl.scenarios.families import build_scenario
from ft_sitl.scenarios.movers import MoverError, movers_from_list, split_dynamic, with_movers
from ft_sitl.scenarios.scenario import GOAL_RADIUS_M, Scenario, ScenarioError

EXPORT_FORMATS = ("ply", "pcd", "obj", "dae", "sdf")
MESH_FORMATS = ("ply", "obj", "stl", "dae")  # what load_mesh reads
SPEC_SUFFIXES = SUFFIXES
USER_FAMILY = "user"
USER_CATEGORY = "user"

PCD_SPACING_M = 0.1
# Refuse clouds larger than this (about 240 MB of float32 points): a spacing too fine.
MAX_PCD_POINTS = 20_000_000
# Dense samples generated per batch while thinning to the PCD spacing (memory bound).
_SAMPLE_BATCH = 1_000_000

SDF_VERSION = "1.6"  # read by Gazebo Classic 9+ (libsdformat 6+) and every Gazebo Sim
# A fixed COLLADA <created>/<modified> stamp keeps the exported bytes reproducible.
_DAE_TIMESTAMP = "2000-01-01T00:00:00Z"
_OBSTACLE_RGBA = (0.6, 0.6, 0.6, 1.0)
_GROUND_RGBA = (0.8, 0.8, 0.8, 1.0)

_SPEC_REQUIRED = ("mesh", "start", "goal")
_SPEC_OPTIONAL = ("name", "takeoff", "bounds", "bounds_min", "bounds_max", "ceiling",
                  "start_yaw_deg", "goal_radius_m", "movers")
_NAME_RE = re.compile(r"[A-Za-z0-9_.-]+")
_COLLADA_NS = "http://www.collada.org/2005/11/COLLADASchema"


# ---- writing files ------------------------------------------------------------------------


def _format_float(x: float) -> str:
    """Shortest exact text for a float that TOML, YAML 1.1 (PyYAML) and XML all read back:
    ``repr``, with a ``.0`` before a bare exponent (PyYAML reads ``1e-05`` as a string)."""
    s = repr(float(x))
    if "e" in s and "." not in s:
        mantissa, exp = s.split("e")
        s = f"{mantissa}.0e{exp}"
    return s


def _floats(values) -> str:
    return " ".join(map(repr, np.asarray(values, dtype=float).ravel().tolist()))


def _ints(values) -> str:
    return " ".join(map(str, np.asarray(values, dtype=np.int64).ravel().tolist()))


def _check_exportable(scenario: Scenario) -> trimesh.Trimesh:
    if not isinstance(scenario, Scenario):
        raise ScenarioError(f"export needs a Scenario, got {type(scenario).__name__}")
    mesh = scenario.mesh
    if len(mesh.faces) == 0:
        raise ScenarioError(f"scenario {scenario.name}: the mesh has no faces; nothing to export")
    return mesh


def ply_bytes(mesh: trimesh.Trimesh, comment: str = "") -> bytes:
    """Binary little-endian PLY with ``double`` vertices and ``int`` face indices."""
    header = ["ply", "format binary_little_endian 1.0"]
    header += [f"comment {line}" for line in comment.splitlines() if line]
    header += [
        f"element vertex {len(mesh.vertices)}",
        "property double x", "property double y", "property double z",
        f"element face {len(mesh.faces)}",
        "property list uchar int vertex_indices",
        "end_header",
    ]
    faces = np.empty(len(mesh.faces), dtype=[("n", "u1"), ("v", "<i4", (3,))])
    faces["n"] = 3
    faces["v"] = mesh.faces
    verts = np.ascontiguousarray(mesh.vertices, dtype="<f8")
    return ("\n".join(header) + "\n").encode("ascii") + verts.tobytes() + faces.tobytes()


def obj_text(mesh: trimesh.Trimesh, comment: str = "") -> str:
    """Wavefront OBJ: one object, ``v`` lines with exact coordinates, 1-based ``f`` lines."""
    lines = [f"# {line}" for line in comment.splitlines() if line]
    lines.append("o obstacles")
    lines += [f"v {x!r} {y!r} {z!r}" for x, y, z in np.asarray(mesh.vertices, float).tolist()]
    lines += [f"f {a} {b} {c}" for a, b, c in (np.asarray(mesh.faces) + 1).tolist()]
    return "\n".join(lines) + "\n"


def _sub(parent: ET.Element, tag: str, text: str | None = None, **attrib) -> ET.Element:
    el = ET.SubElement(parent, tag, {k: str(v) for k, v in attrib.items()})
    if text is not None:
        el.text = text
    return el


def _xml_bytes(root: ET.Element, comment: str = "") -> bytes:
    ET.indent(root, space="  ")
    body = ET.tostring(root, encoding="unicode")
    head = '<?xml version="1.0" encoding="utf-8"?>\n'
    if comment:
        text = comment.replace("--", "- -")  # "--" may not appear inside an XML comment
        head += f"<!--\n{text}\n-->\n"
    return (head + body + "\n").encode("utf-8")


def _float_source(mesh_el: ET.Element, sid: str, data: np.ndarray) -> None:
    src = _sub(mesh_el, "source", id=sid)
    _sub(src, "float_array", _floats(data), id=f"{sid}-array", count=data.size)
    tech = _sub(src, "technique_common")
    acc = _sub(tech, "accessor", source=f"#{sid}-array", count=len(data), stride=3)
    for axis in "XYZ":
        _sub(acc, "param", name=axis, type="float")


def dae_bytes(mesh: trimesh.Trimesh, title: str = "obstacles", comment: str = "") -> bytes:
    """COLLADA 1.4.1: Z up, metres, one triangle list with per-face normals and one material."""
    root = ET.Element("COLLADA", xmlns=_COLLADA_NS, version="1.4.1")
    asset = _sub(root, "asset")
    _sub(_sub(asset, "contributor"), "authoring_tool", f"ft_sitl {__version__}")
    _sub(asset, "created", _DAE_TIMESTAMP)
    _sub(asset, "modified", _DAE_TIMESTAMP)
    _sub(asset, "title", title)
    _sub(asset, "unit", name="meter", meter="1")
    _sub(asset, "up_axis", "Z_UP")

    effect = _sub(_sub(root, "library_effects"), "effect", id="obstacle-effect")
    lambert = _sub(_sub(_sub(effect, "profile_COMMON"), "technique", sid="common"), "lambert")
    _sub(_sub(lambert, "diffuse"), "color", " ".join(map(str, _OBSTACLE_RGBA)), sid="diffuse")
    material = _sub(_sub(root, "library_materials"), "material", id="obstacle-material",
                    name="obstacle")
    _sub(material, "instance_effect", url="#obstacle-effect")

    geometry = _sub(_sub(root, "library_geometries"), "geometry", id="obstacles-mesh",
                    name="obstacles")
    mesh_el = _sub(geometry, "mesh")
    _float_source(mesh_el, "obstacles-positions", np.asarray(mesh.vertices, float))
    _float_source(mesh_el, "obstacles-normals", np.asarray(mesh.face_normals, float))
    verts = _sub(mesh_el, "vertices", id="obstacles-vertices")
    _sub(verts, "input", semantic="POSITION", source="#obstacles-positions")
    tris = _sub(mesh_el, "triangles", material="obstacle", count=len(mesh.faces))
    _sub(tris, "input", semantic="VERTEX", source="#obstacles-vertices", offset=0)
    _sub(tris, "input", semantic="NORMAL", source="#obstacles-normals", offset=1)
    faces = np.asarray(mesh.faces, dtype=np.int64)
    face_id = np.repeat(np.arange(len(faces)), 3).reshape(-1, 3)
    _sub(tris, "p", _ints(np.stack([faces, face_id], axis=-1)))  # v0 n v1 n v2 n per face

    scene = _sub(_sub(root, "library_visual_scenes"), "visual_scene", id="scene", name="scene")
    node = _sub(scene, "node", id="obstacles", name="obstacles", type="NODE")
    inst = _sub(node, "instance_geometry", url="#obstacles-mesh")
    tech = _sub(_sub(inst, "bind_material"), "technique_common")
    _sub(tech, "instance_material", symbol="obstacle", target="#obstacle-material")
    _sub(_sub(root, "scene"), "instance_visual_scene", url="#scene")
    return _xml_bytes(root, comment)


def _rgba(values) -> str:
    return " ".join(map(str, values))


def sdf_bytes(scenario: Scenario, dae_path: Path, comment: str = "") -> bytes:
    """A Gazebo SDF world: sun, ground plane under the scenario area, static obstacles."""
    # The mesh URI is ``file://`` + the DAE's absolute path. Gazebo Classic resolves
    # ``file://`` (and ``model://``) URIs but not paths relative to the world file; Gazebo
    # Sim resolves ``file://`` too (relative URIs only with recent libsdformat). So the
    # world only works where the DAE stays: export again after moving the files.
    uri = "file://" + Path(os.path.abspath(dae_path)).as_posix()
    world_name = re.sub(r"[^A-Za-z0-9_]", "_", scenario.name)
    root = ET.Element("sdf", version=SDF_VERSION)
    world = _sub(root, "world", name=world_name)

    sun = _sub(world, "light", type="directional", name="sun")
    _sub(sun, "cast_shadows", "true")
    _sub(sun, "pose", "0 0 10 0 0 0")
    _sub(sun, "diffuse", "0.8 0.8 0.8 1")
    _sub(sun, "specular", "0.2 0.2 0.2 1")
    att = _sub(sun, "attenuation")
    for tag, value in (("range", "1000"), ("constant", "0.9"), ("linear", "0.01"),
                       ("quadratic", "0.001")):
        _sub(att, tag, value)
    _sub(sun, "direction", "-0.5 0.1 -0.9")

    lo, hi = scenario.bounds_min, scenario.bounds_max
    centre = (lo[:2] + hi[:2]) / 2
    size = 2.0 * (hi[:2] - lo[:2])  # the area and a margin as wide again around it
    ground = _sub(world, "model", name="ground_plane")
    _sub(ground, "static", "true")
    _sub(ground, "pose", f"{_floats(centre)} 0 0 0 0")
    link = _sub(ground, "link", name="link")
    for kind in ("collision", "visual"):
        el = _sub(link, kind, name=kind)
        plane = _sub(_sub(el, "geometry"), "plane")
        _sub(plane, "normal", "0 0 1")
        _sub(plane, "size", _floats(size))
        if kind == "visual":
            mat = _sub(el, "material")
            _sub(mat, "ambient", _rgba(_GROUND_RGBA))
            _sub(mat, "diffuse", _rgba(_GROUND_RGBA))

    model = _sub(world, "model", name="obstacles")
    _sub(model, "static", "true")
    _sub(model, "pose", "0 0 0 0 0 0")
    link = _sub(model, "link", name="link")
    for kind in ("collision", "visual"):
        el = _sub(link, kind, name=kind)
        _sub(_sub(_sub(el, "geometry"), "mesh"), "uri", uri)
    return _xml_bytes(root, comment)


# ---- point cloud --------------------------------------------------------------------------


def _batched(counts: np.ndarray):
    """For items producing ``counts[i]`` samples each: batches of (item, k-th sample of it)
    with at most ``_SAMPLE_BATCH`` samples per batch (a huge item spans several)."""
    ends = np.cumsum(counts)
    total = int(ends[-1]) if len(ends) else 0
    for lo in range(0, total, _SAMPLE_BATCH):
        g = np.arange(lo, min(lo + _SAMPLE_BATCH, total), dtype=np.int64)
        item = np.searchsorted(ends, g, side="right")
        yield item, g - (ends[item] - counts[item])


def _segment_samples(a: np.ndarray, b: np.ndarray, step: float):
    """Batches of points every <= ``step`` along each segment a[i] -> b[i], ends included."""
    n = np.maximum(np.ceil(np.linalg.norm(b - a, axis=1) / step), 1).astype(np.int64)
    for seg, k in _batched(n + 1):
        t = k / n[seg]
        yield a[seg] + t[:, None] * (b[seg] - a[seg])


def _triangle_frames(tris: np.ndarray):
    """Each triangle relabelled (a, b, c) with a -> b its longest edge, plus the in-plane
    frame: u along a -> b, v towards c; L = |b - a|, (cu, cv) = c in that frame."""
    edge_len = np.linalg.norm(tris[:, [1, 2, 0]] - tris, axis=2)  # edges 0-1, 1-2, 2-0
    k = np.argmax(edge_len, axis=1)
    idx = np.arange(len(tris))
    a, b, c = tris[idx, k], tris[idx, (k + 1) % 3], tris[idx, (k + 2) % 3]
    L = edge_len[idx, k]
    u = (b - a) / L[:, None]
    w = c - a
    cu = np.einsum("ij,ij->i", w, u)
    perp = w - cu[:, None] * u
    cv = np.linalg.norm(perp, axis=1)
    return a, b, c, L, cu, cv


def _triangle_grid_samples(tris: np.ndarray, step: float):
    """Batches of points of a square grid of pitch ``step`` laid in each triangle's plane
    from its longest edge, those inside the triangle (exactly on it: barycentric)."""
    a, b, c, L, cu, cv = _triangle_frames(tris)
    keep = (L > 0) & (cv > 1e-12 * np.maximum(L, 1.0))  # slivers: their edges cover them
    a, b, c, L, cu, cv = a[keep], b[keep], c[keep], L[keep], cu[keep], cv[keep]
    nu = np.floor(L / step).astype(np.int64) + 1
    nv = np.floor(cv / step).astype(np.int64) + 1
    for t, local in _batched(nu * nv):
        x = (local // nv[t]) * step
        y = (local % nv[t]) * step
        w2 = y / cv[t]
        w1 = (x - w2 * cu[t]) / L[t]
        w0 = 1.0 - w1 - w2
        w = np.stack([w0, w1, w2], axis=1)
        inside = np.all(w >= -1e-9, axis=1)
        w = np.clip(w[inside], 0.0, None)
        w /= w.sum(axis=1, keepdims=True)
        t = t[inside]
        yield w[:, :1] * a[t] + w[:, 1:2] * b[t] + w[:, 2:] * c[t]


def surface_points(mesh: trimesh.Trimesh, spacing_m: float = PCD_SPACING_M) -> np.ndarray:
    """Points on the mesh surface on a regular spacing: the surface is sampled densely
    (every edge and a grid in every triangle, pitch ``spacing_m / 2``), then thinned like
    PCL's voxel grid to the sample nearest the centre of each cubic cell of side
    ``spacing_m`` (cells aligned with the mesh bounds). Every point lies on a triangle;
    every part of the surface is within about ``spacing_m`` of a point. Deterministic;
    sorted by cell. Returns (n, 3) float64."""
    if isinstance(spacing_m, bool) or not isinstance(spacing_m, (int, float)) or not (
        math.isfinite(spacing_m) and spacing_m > 0
    ):
        raise ScenarioError(f"pcd_spacing_m: must be a positive number of metres, "
                            f"got {spacing_m!r}")
    spacing = float(spacing_m)
    if len(mesh.faces) == 0:
        return np.zeros((0, 3))
    estimate = float(mesh.area) / spacing**2
    if estimate > MAX_PCD_POINTS:
        raise ScenarioError(
            f"pcd_spacing_m: {spacing} m would give about {estimate:.3g} points on "
            f"{mesh.area:.0f} m^2 of surface (limit {MAX_PCD_POINTS}); use a coarser spacing"
        )
    origin = mesh.bounds[0]
    dims = np.floor((mesh.bounds[1] - origin) / spacing).astype(np.int64) + 1
    step = spacing / 2
    verts = np.asarray(mesh.vertices, dtype=float)
    edges = np.asarray(mesh.edges_unique)

    batches = itertools.chain(
        _segment_samples(verts[edges[:, 0]], verts[edges[:, 1]], step),
        _triangle_grid_samples(np.asarray(mesh.triangles, dtype=float), step),
    )
    kept: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
    pending = 0
    for pts in batches:
        cell = np.clip(np.floor((pts - origin) / spacing).astype(np.int64), 0, dims - 1)
        key = (cell[:, 0] * dims[1] + cell[:, 1]) * dims[2] + cell[:, 2]
        d2 = np.sum((pts - (origin + (cell + 0.5) * spacing)) ** 2, axis=1)
        kept.append(_nearest_per_cell(pts, key, d2))
        pending += len(kept[-1][0])
        if pending > 4 * _SAMPLE_BATCH:  # bound the memory held between batches
            kept = [_nearest_per_cell(*map(np.concatenate, zip(*kept, strict=True)))]
            pending = len(kept[0][0])
    if not kept:
        return np.zeros((0, 3))
    return _nearest_per_cell(*map(np.concatenate, zip(*kept, strict=True)))[0]


def _nearest_per_cell(pts: np.ndarray, key: np.ndarray, d2: np.ndarray):
    """The sample nearest its cell centre, one per cell key, sorted by key. Stable: on a
    tie the earlier sample stays, so the result depends on nothing but the input order."""
    order = np.lexsort((d2, key))
    first = np.ones(len(order), dtype=bool)
    first[1:] = key[order[1:]] != key[order[:-1]]
    pick = order[first]
    return pts[pick], key[pick], d2[pick]


def pcd_bytes(points: np.ndarray) -> bytes:
    """PCD v0.7, fields x y z float32, binary data (what ``pcl::io::loadPCDFile`` reads)."""
    pts = np.ascontiguousarray(points, dtype="<f4")
    n = len(pts)
    header = (
        "# .PCD v0.7 - Point Cloud Data file format\n"
        "VERSION 0.7\n"
        "FIELDS x y z\n"
        "SIZE 4 4 4\n"
        "TYPE F F F\n"
        "COUNT 1 1 1\n"
        f"WIDTH {n}\n"
        "HEIGHT 1\n"
        "VIEWPOINT 0 0 0 1 0 0 0\n"
        f"POINTS {n}\n"
        "DATA binary\n"
    )
    return header.encode("ascii") + pts.tobytes()


# ---- export -------------------------------------------------------------------------------


def _describe(scenario: Scenario) -> str:
    s = scenario
    return "\n".join([
        f"ft_sitl {__version__} scenario {s.name} (family {s.family}, index {s.index}, "
        f"seed {s.seed}, category {s.category})",
        "world frame ENU (x east, y north, z up), metres; obstacles only, floor z = 0",
        f"bounds_min {s.bounds_min.tolist()} bounds_max {s.bounds_max.tolist()} "
        f"(ceiling {s.ceiling} m)",
        f"start {s.start.tolist()} yaw {s.start_yaw!r} rad; goal {s.goal.tolist()} "
        f"within {s.goal_radius_m} m",
        f"mesh sha256 {s.mesh_digest()}",
    ])


def _normalise_format(fmt, path: Path) -> tuple[str, Path]:
    valid = ", ".join(EXPORT_FORMATS)
    suffix = path.suffix.lower().lstrip(".")
    if fmt is None:
        if not suffix:
            raise ScenarioError(f"{path}: no file suffix to tell the format; give fmt, "
                                f"one of {valid}")
        fmt = suffix
        if fmt not in EXPORT_FORMATS:
            raise ScenarioError(f"{path}: unknown export format {suffix!r} (from the suffix); "
                                f"valid formats: {valid}")
        return fmt, path
    if not isinstance(fmt, str):
        raise ScenarioError(f"fmt: must be a string, one of {valid}; got {fmt!r}")
    fmt = fmt.lower().lstrip(".")
    if fmt not in EXPORT_FORMATS:
        raise ScenarioError(f"unknown export format {fmt!r}; valid formats: {valid}")
    if not suffix:
        return fmt, path.with_name(f"{path.name}.{fmt}")
    if suffix != fmt:
        raise ScenarioError(f"{path}: the suffix .{suffix} does not match the format {fmt!r}; "
                            f"name the file *.{fmt}")
    return fmt, path


def _write_files(files: dict[Path, bytes]) -> list[Path]:
    for path in files:
        if not path.parent.is_dir():
            raise ScenarioError(f"{path}: cannot write: the directory {path.parent} does not "
                                "exist")
        if path.is_dir():
            raise ScenarioError(f"{path}: cannot write: it is a directory")
    for path, data in files.items():
        try:
            path.write_bytes(data)
        except OSError as exc:
            raise ScenarioError(f"{path}: cannot write the file ({exc.strerror})") from None
    return list(files)


def export_scenario(scenario: Scenario, path, fmt: str | None = None, *,
                    pcd_spacing_m: float = PCD_SPACING_M) -> list[Path]:
    """Write the scenario's obstacles as ``fmt`` (one of :data:`EXPORT_FORMATS`; default:
    from the suffix of ``path``, which gets ``.fmt`` when it has none). Returns the files
    written: ``[path]``, or ``[world.sdf, world.dae]`` for ``sdf``."""
    path = Path(path)
    fmt, path = _normalise_format(fmt, path)
    mesh = _check_exportable(scenario)
    comment = _describe(scenario)
    if fmt == "ply":
        files = {path: ply_bytes(mesh, comment)}
    elif fmt == "obj":
        files = {path: obj_text(mesh, comment).encode("utf-8")}
    elif fmt == "dae":
        files = {path: dae_bytes(mesh, scenario.name, comment)}
    elif fmt == "pcd":
        files = {path: pcd_bytes(surface_points(mesh, pcd_spacing_m))}
    else:  # sdf
        dae = path.with_suffix(".dae")
        files = {path: sdf_bytes(scenario, dae, comment),
                 dae: dae_bytes(mesh, scenario.name, comment)}
    return _write_files(files)


def write_scenario_spec(scenario: Scenario, path, *, mesh_path=None) -> list[Path]:
    """Write a TOML or YAML spec (by the suffix of ``path``) that :func:`load_scenario` reads
    back into this scenario (category ``user``, family = this scenario's name).

    The spec refers to ``mesh_path`` (an existing PLY/OBJ/STL/DAE file; written relative to
    the spec's directory). Without it, the exact PLY ``<spec stem>.ply`` is written beside
    the spec. Returns the files written (the spec first)."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in SPEC_SUFFIXES:
        raise ScenarioError(f"{path}: a scenario spec must be named *.toml, *.yaml or *.yml")
    _check_exportable(scenario)
    files: dict[Path, bytes] = {}
    if mesh_path is None:
        mesh_file = path.with_suffix(".ply")
        mesh_bytes = ply_bytes(scenario.mesh, _describe(scenario))
    else:
        mesh_file = Path(mesh_path)
        if mesh_file.suffix.lower().lstrip(".") not in MESH_FORMATS:
            raise ScenarioError(f"mesh_path: {mesh_file} is not a mesh load_scenario reads; "
                                f"use {', '.join('.' + s for s in MESH_FORMATS)}")
        if not mesh_file.is_file():
            raise ScenarioError(f"mesh_path: {mesh_file} is not an existing file")
        mesh_bytes = None
    try:
        ref = Path(os.path.relpath(os.path.abspath(mesh_file),
                                   os.path.abspath(path.parent))).as_posix()
    except ValueError:  # another drive (Windows)
        ref = Path(os.path.abspath(mesh_file)).as_posix()
    s = scenario
    values = {
        # a user scenario keeps its family; a generated one is named after its source
        "name": s.family if s.category == USER_CATEGORY else s.name,
        "mesh": ref,
        "start": s.start,
        "goal": s.goal,
        "takeoff": s.takeoff,
        "bounds_min": s.bounds_min,
        "bounds_max": s.bounds_max,
        "ceiling": s.ceiling,
        "start_yaw_deg": math.degrees(s.start_yaw),
        "goal_radius_m": s.goal_radius_m,
    }
    sep = " = " if suffix == ".toml" else ": "
    lines = [f"# {line}" for line in _describe(s).splitlines()]
    for key, value in values.items():
        if isinstance(value, str):
            text = json.dumps(value)  # a valid TOML basic string and YAML double-quoted one
        elif isinstance(value, np.ndarray):
            text = "[" + ", ".join(_format_float(v) for v in value.tolist()) + "]"
        else:
            text = _format_float(value)
        lines.append(f"{key}{sep}{text}")
    if s.movers is not None and s.movers.count:  # each mover as movers_from_list reads it
        items = s.movers.as_list()
        if suffix == ".toml":  # (JSON numbers, strings, booleans and arrays are TOML's too)
            for it in items:
                lines += ["", "[[movers]]"] + [f"{k} = {json.dumps(v)}" for k, v in it.items()]
        else:  # a YAML list of flow mappings (JSON is YAML)
            lines += ["movers:"] + [f"  - {json.dumps(it)}" for it in items]
    files[path] = ("\n".join(lines) + "\n").encode("utf-8")
    if mesh_bytes is not None:
        files[mesh_file] = mesh_bytes
    return _write_files(files)


# ---- import -------------------------------------------------------------------------------


def _sha256_file(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _collada_asset(path: Path) -> tuple[float, str]:
    """(metres per unit, up axis) from a COLLADA file's top-level ``<asset>``."""
    meter, up = 1.0, "Y_UP"  # the COLLADA defaults
    try:
        for _, el in ET.iterparse(path, events=("end",)):
            tag = el.tag.rsplit("}", 1)[-1]
            if tag == "unit" and el.get("meter") is not None:
                try:
                    meter = float(el.get("meter"))
                except ValueError:
                    raise ScenarioError(f"{path}: <unit meter={el.get('meter')!r}> is not "
                                        "a number") from None
            elif tag == "up_axis" and el.text:
                up = el.text.strip()
            elif tag == "asset":
                break
    except ET.ParseError as exc:
        line, col = exc.position
        raise ScenarioError(f"{path}: not valid XML (line {line}, column {col}): "
                            f"{exc}") from None
    if not (math.isfinite(meter) and meter > 0):
        raise ScenarioError(f"{path}: <unit meter> must be a positive number, got {meter}")
    if up not in ("X_UP", "Y_UP", "Z_UP"):
        raise ScenarioError(f"{path}: <up_axis> must be X_UP, Y_UP or Z_UP, got {up!r}")
    return meter, up


# Rotations taking a COLLADA asset's up axis to +z (right-handed, as Gazebo does).
_TO_Z_UP = {
    "X_UP": np.array([[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]]),
    "Y_UP": np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]]),
    "Z_UP": np.eye(3),
}


def load_mesh(path) -> trimesh.Trimesh:
    """One triangle mesh from a PLY, OBJ, STL or DAE file (ENU metres, z up).

    PLY and OBJ vertices and faces keep the file's order and values (no merging), so an
    exported PLY or OBJ comes back bit for bit. STL and DAE corners are merged by position
    (STL shares none; COLLADA readers split them per normal), and pycollada reads DAE
    coordinates as float32. Scenes (several objects, COLLADA nodes) are flattened with their
    transforms into one mesh. COLLADA ``<unit>`` and ``<up_axis>`` are applied, so a
    Y-up or centimetre file comes in z-up metres, as Gazebo shows it. Raises
    :class:`ScenarioError` naming the file when it is missing, unreadable, empty or not a
    mesh."""
    path = Path(path)
    suffix = path.suffix.lower().lstrip(".")
    if suffix not in MESH_FORMATS:
        raise ScenarioError(
            f"{path}: not a mesh format ({'.' + suffix if suffix else 'no suffix'}); "
            f"use {', '.join('.' + s for s in MESH_FORMATS)}"
        )
    if not path.exists():
        raise ScenarioError(f"{path}: mesh file not found")
    if not path.is_file():
        raise ScenarioError(f"{path}: not a file")
    try:
        with open(path, "rb") as fh:
            empty = not fh.read(1)
    except OSError as exc:
        raise ScenarioError(f"{path}: cannot read the mesh file ({exc.strerror})") from None
    if empty:
        raise ScenarioError(f"{path}: the mesh file is empty")
    meter, up = _collada_asset(path) if suffix == "dae" else (1.0, "Z_UP")
    try:
        loaded = trimesh.load_scene(str(path), file_type=suffix, process=False)
        mesh = loaded.to_mesh() if len(loaded.geometry) else None
    except Exception as exc:  # trimesh and its readers raise many types; report, not crash
        raise ScenarioError(f"{path}: cannot read it as {suffix.upper()} "
                            f"({type(exc).__name__}: {exc})") from None
    if mesh is None or not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise ScenarioError(f"{path}: holds no triangles")
    verts = np.asarray(mesh.vertices, dtype=float)
    faces = np.asarray(mesh.faces, dtype=np.int64)
    if not np.all(np.isfinite(verts)):
        raise ScenarioError(f"{path}: has non-finite vertex coordinates")
    if faces.min() < 0 or faces.max() >= len(verts):
        raise ScenarioError(f"{path}: a face refers to a vertex that does not exist")
    if meter != 1.0 or up != "Z_UP":
        verts = meter * verts @ _TO_Z_UP[up].T
    out = trimesh.Trimesh(vertices=verts, faces=faces, process=False)
    if suffix in ("stl", "dae"):  # corners unshared (STL) or split per normal (COLLADA)
        out.merge_vertices()
    return out


def _fmt(v: np.ndarray) -> str:
    return "[" + ", ".join(f"{x:g}" for x in v) + "]"


def load_scenario(spec_path) -> Scenario:
    """A :class:`Scenario` from a TOML/YAML spec and its mesh (see the module docstring):
    family = the spec's ``name`` (default ``user``), index 1, seed 0, category ``user``."""
    spec_path = Path(spec_path)
    w = str(spec_path)
    doc = read_document(spec_path, what="spec file",
                        expected=f"{', '.join(_SPEC_REQUIRED)}, ...", error=ScenarioError)
    t = Table(doc, w, error=ScenarioError)
    t.check_keys(_SPEC_REQUIRED + _SPEC_OPTIONAL)
    t.require(_SPEC_REQUIRED)

    name = doc.get("name", USER_FAMILY)
    if not isinstance(name, str) or not _NAME_RE.fullmatch(name):
        raise ScenarioError(f"{w}: name: must be a non-empty string of letters, digits, "
                            f"'_', '-' or '.', got {name!r}")
    mesh_ref = doc["mesh"]
    if not isinstance(mesh_ref, str) or not mesh_ref.strip():
        raise ScenarioError(f"{w}: mesh: must be a file path (relative to the spec file), "
                            f"got {mesh_ref!r}")
    mesh_file = Path(mesh_ref)
    if not mesh_file.is_absolute():
        mesh_file = spec_path.parent / mesh_file

    start = np.array(t.vector3("start"))
    goal = np.array(t.vector3("goal"))
    for key, p in (("start", start), ("goal", goal)):
        if p[2] < 0:
            raise ScenarioError(f"{w}: {key}: z = {p[2]:g} is below the floor (z = 0)")
    if "takeoff" in doc:
        takeoff = np.array(t.vector3("takeoff"))
        if takeoff[2] != 0:
            raise ScenarioError(f"{w}: takeoff: must be on the floor (z = 0), "
                                f"got z = {takeoff[2]:g}")
    else:
        takeoff = np.array([start[0], start[1], 0.0])

    lo = hi = None
    if "bounds" in doc:
        if "bounds_min" in doc or "bounds_max" in doc:
            raise ScenarioError(f"{w}: bounds: give either 'bounds' or "
                                "'bounds_min'/'bounds_max', not both")
        if not isinstance(doc["bounds"], dict):
            raise t.fail("bounds", f"must be a table {{min = [x, y, z], max = [x, y, z]}}, "
                                   f"got {doc['bounds']!r}")
        b = t.table("bounds")
        b.check_keys(("min", "max"))
        lo = np.array(b.vector3("min")) if "min" in b else None
        hi = np.array(b.vector3("max")) if "max" in b else None
        lo_key, hi_key = "bounds.min", "bounds.max"
    else:
        lo = np.array(t.vector3("bounds_min")) if "bounds_min" in doc else None
        hi = np.array(t.vector3("bounds_max")) if "bounds_max" in doc else None
        lo_key, hi_key = "bounds_min", "bounds_max"
    ceiling = t.number("ceiling", None) if "ceiling" in doc else None
    if ceiling is not None and ceiling <= 0:
        raise ScenarioError(f"{w}: ceiling: must be above the floor (> 0 m), got {ceiling:g}")
    if hi is not None and ceiling is not None and not math.isclose(hi[2], ceiling):
        raise ScenarioError(f"{w}: ceiling: {ceiling:g} disagrees with {hi_key} z = "
                            f"{hi[2]:g}; give one of them")
    if hi is None and ceiling is None:
        raise ScenarioError(f"{w}: missing key 'ceiling' (the flight ceiling, m): needed "
                            f"when {hi_key} is not given")
    if lo is not None and lo[2] != 0:
        raise ScenarioError(f"{w}: {lo_key}: z must be 0 (the floor), got {lo[2]:g}")
    goal_radius = GOAL_RADIUS_M
    if "goal_radius_m" in doc:
        goal_radius = t.number("goal_radius_m")
        if goal_radius <= 0:
            raise ScenarioError(f"{w}: goal_radius_m: must be positive, got {goal_radius:g}")
    if "start_yaw_deg" in doc:
        start_yaw = math.radians(t.number("start_yaw_deg"))
    else:
        d = goal - start
        start_yaw = math.atan2(d[1], d[0]) if np.hypot(d[0], d[1]) > 0 else 0.0

    try:
        mesh = load_mesh(mesh_file)
    except ScenarioError as exc:
        raise ScenarioError(f"{w}: mesh: {exc}") from None

    if lo is None or hi is None:
        pts = np.vstack([mesh.bounds, start, goal, takeoff])
        lo = np.array([*pts[:, :2].min(axis=0), 0.0]) if lo is None else lo
        hi = np.array([*pts[:, :2].max(axis=0), ceiling]) if hi is None else hi
    if ceiling is not None:
        hi[2] = ceiling
    if np.any(hi <= lo):
        raise ScenarioError(f"{w}: bounds: max {_fmt(hi)} must exceed min {_fmt(lo)} on "
                            "every axis")
    for key, p in (("start", start), ("goal", goal), ("takeoff", takeoff)):
        if np.any(p < lo) or np.any(p > hi):
            raise ScenarioError(f"{w}: {key}: {_fmt(p)} lies outside the bounds {_fmt(lo)} "
                                f".. {_fmt(hi)} (ceiling {hi[2]:g} m)")

    provenance = {
        "generator": "ft_sitl.scenarios.io.load_scenario",
        "ft_sitl_version": __version__,
        "spec": str(spec_path.resolve()),
        "spec_sha256": _sha256_file(spec_path),
        "mesh": str(mesh_file.resolve()),
        "mesh_sha256": _sha256_file(mesh_file),
        "obstacle_count": int(mesh.body_count),
        "seed": 0,
        "index": 1,
    }
    movers = doc.get("movers")
    if movers is not None and not isinstance(movers, (dict, list)):
        raise ScenarioError(f"{w}: movers: must be a table of mover settings or a list of "
                            f"movers (tables), got {movers!r}")
    try:
        sc = Scenario(family=name, index=1, seed=0, category=USER_CATEGORY, mesh=mesh,
                      bounds_min=lo, bounds_max=hi, takeoff=takeoff, start=start,
                      start_yaw=start_yaw, goal=goal, goal_radius_m=goal_radius,
                      provenance=provenance)
    except ScenarioError as exc:  # every field was checked above; name the file regardless
        raise ScenarioError(f"{w}: {exc}") from None
    try:
        if isinstance(movers, dict):  # settings: placed for the scenario's seed
            return with_movers(sc, movers, sc.seed, owner=f"{w}: movers")
        if isinstance(movers, list):  # each mover given
            return dataclasses.replace(sc, movers=movers_from_list(movers, f"{w}: movers"))
    except MoverError as exc:
        raise ScenarioError(str(exc)) from None
    return sc


def scenario_from_spec(spec):
    """A scenario named on a command line: ``FAMILY:INDEX[:SEED]`` (e.g. ``forest:3``) or a
    scenario spec file (.yaml, .yml, .toml), optionally followed by ``+dynamic(KEY=VALUE,
    ...)``: moving obstacles (scenarios.movers settings, short keys such as ``speed``
    allowed) placed for the scenario's seed, e.g. ``forest:3+dynamic(count=8, speed=1.5)``;
    their clock starts at simulation time 0. None and Scenario objects pass through.
    ValueError names what is wrong."""
    if spec is None or isinstance(spec, Scenario):
        return spec
    if not isinstance(spec, str):
        raise ValueError(f"scenario: {spec!r} is not FAMILY:INDEX[:SEED] or a spec file")

    try:  # (a spec file whose path holds a '+' is taken whole)
        head, dynamic = (spec, None) if Path(spec).is_file() else split_dynamic(spec)
    except MoverError as exc:  # (its message names the spec)
        raise ValueError(str(exc)) from None
    head = head.strip()
    try:
        if Path(head).suffix.lower() in (".yaml", ".yml", ".toml"):
            sc = load_scenario(Path(head))
        else:
            parts = head.split(":")
            if len(parts) not in (2, 3):
                raise ValueError(f"scenario {spec!r}: expected FAMILY:INDEX[:SEED] (e.g. "
                                 "forest:3) or a scenario spec file (.yaml, .toml), "
                                 "optionally followed by +dynamic(KEY=VALUE, ...)")
            try:
                index, seed = int(parts[1]), int(parts[2]) if len(parts) == 3 else 0
            except ValueError:
                raise ValueError(f"scenario {spec!r}: INDEX and SEED must be integers") \
                    from None
            sc = build_scenario(parts[0], index, seed)
        if dynamic is None:
            return sc
        if sc.movers is not None:
            raise ValueError(f"scenario {spec!r}: {head} has movers of its own; give them "
                             "in the spec file or in +dynamic(...), not both")
        return with_movers(sc, dynamic, sc.seed, owner="dynamic")
    except (ScenarioError, MoverError) as exc:
        raise ValueError(f"scenario {spec!r}: {exc}") from None
