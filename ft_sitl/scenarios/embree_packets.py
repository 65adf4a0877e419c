"""First-hit ray queries in packets of 16 through Embree 4's C API.

``embreex`` (the binding trimesh uses) exposes only Embree's single-ray query
(``rtcIntersect1``, one call per ray). A depth camera's rays leave one point through
neighbouring pixels, the coherent case Embree's packet traversal (``rtcIntersect16``) is
built for. This module binds the few functions it needs with ``ctypes`` from the Embree
library that the ``embreex`` wheel ships, builds the same scene trimesh builds (the same
float32 vertices, shifted and scaled as trimesh does, the same triangle order, the robust
scene flag) and traverses runs of 16 pixels of a row per call from a compiled loop.

With one scene over all triangles (``instances=False``) every ray's first-hit triangle is
the one the single-ray query reports for the same float32 ray: the packet kernels run the
same intersection test per lane. ``tests/scenarios`` checks this triangle by triangle
against ``embreex`` on scenario meshes; ``bench_camera`` times both (the packets are ~1.3x
faster on 160 x 120 frames). By default each connected piece of the mesh is an instance in
its own principal-axes frame (:class:`PacketScene`): faster still, and the same first hits
but for rays through edges and silhouettes (``bench_camera_families``).

:func:`packet_scene` returns None when the library or one of its functions cannot be
loaded; callers then use ``embreex``'s single-ray query.
"""

from __future__ import annotations

import ctypes
import glob
import os

import numpy as np
from numba import njit
from trimesh.graph import connected_component_labels

from ft_sitl import numeric_env

__all__ = ["PacketScene", "packet_scene"]

_U64 = ctypes.c_uint64
# rtcore_common.h / rtcore_buffer.h / rtcore_scene.h constants
_BUFFER_TYPE_INDEX, _BUFFER_TYPE_VERTEX = 0, 1
_FORMAT_UINT3, _FORMAT_FLOAT3 = 0x5003, 0x9003
_GEOMETRY_TYPE_TRIANGLE = 0
_GEOMETRY_TYPE_INSTANCE = 121
_FORMAT_FLOAT3X4_COLUMN_MAJOR = 0x9234
_SCENE_FLAG_ROBUST = 1 << 2  # embreex's EmbreeScene(robust=True), trimesh's default
#: instances only for meshes of at most this many connected pieces ...
MAX_INSTANCES = 10_000
#: ... of at least this many triangles on average (Perlin's blobs have 12)
MIN_PIECE_FACES = 4
_INVALID_ID = 0xFFFFFFFF

# RTCRayHit16 (rtcore_ray.h), in 4-byte words: twelve ray arrays of 16 (org_x, org_y,
# org_z, tnear, dir_x, dir_y, dir_z, time, tfar, mask, id, flags), then the hit (Ng_x,
# Ng_y, Ng_z, u, v, primID, geomID, instID[levels][16], ...). 64-byte aligned.
_W = 16
_OX, _OY, _OZ, _TNEAR, _DX, _DY, _DZ, _TIME, _TFAR, _MASK, _ID, _FLAGS = (
    k * _W for k in range(12))
_PRIM, _GEOM, _INST = 17 * _W, 18 * _W, 19 * _W
_PACKET_BYTES = 4096  # > the struct with any instance level count Embree is built with

_LIB = None
_LIB_TRIED = False
_DEVICE = None


def _library():
    """The Embree 4 library of the embreex wheel with the functions used, or None."""
    global _LIB, _LIB_TRIED
    if _LIB_TRIED:
        return _LIB
    _LIB_TRIED = True
    try:
        # Embree: loaded only when a depth camera is built
        import embreex

        here = os.path.dirname(embreex.__file__)
        paths = sorted(glob.glob(os.path.join(here, "..", "embreex.libs", "libembree4*"))) \
            + sorted(glob.glob(os.path.join(here, "libembree4*")))
        if not paths:
            return None
        lib = ctypes.CDLL(paths[0])
        sig = {
            "rtcNewDevice": (_U64, [ctypes.c_char_p]),
            "rtcNewScene": (_U64, [_U64]),
            "rtcSetSceneFlags": (None, [_U64, ctypes.c_int]),
            "rtcNewGeometry": (_U64, [_U64, ctypes.c_int]),
            "rtcSetNewGeometryBuffer": (_U64, [_U64, ctypes.c_int, ctypes.c_uint,
                                               ctypes.c_int, ctypes.c_size_t,
                                               ctypes.c_size_t]),
            "rtcCommitGeometry": (None, [_U64]),
            "rtcAttachGeometry": (ctypes.c_uint, [_U64, _U64]),
            "rtcReleaseGeometry": (None, [_U64]),
            "rtcCommitScene": (None, [_U64]),
            "rtcSetGeometryInstancedScene": (None, [_U64, _U64]),
            "rtcSetGeometryTransform": (None, [_U64, ctypes.c_uint, ctypes.c_int,
                                               ctypes.c_void_p]),
            "rtcReleaseScene": (None, [_U64]),
            "rtcGetDeviceError": (ctypes.c_int, [_U64]),
            # pointers passed as 64-bit integers (the same registers on x86-64 / arm64):
            # numba calls it with array addresses
            "rtcIntersect16": (None, [_U64, _U64, _U64, _U64]),
        }
        for name, (res, args) in sig.items():
            fn = getattr(lib, name)
            fn.restype, fn.argtypes = res, args
    except (ImportError, OSError, AttributeError):
        return None
    _LIB = lib
    return lib


def _device(lib):
    global _DEVICE
    if _DEVICE is None:
        # the instruction set ft_sitl.numeric_env pins (None: Embree's choice)
        config = numeric_env.embree_config()
        dev = lib.rtcNewDevice(config.encode() if config else None)
        _DEVICE = dev or 0
    return _DEVICE or None


class PacketScene:
    """An Embree scene over float32 ``vertices`` (V, 3) and ``faces`` (F, 3), queried in
    packets of 16 rays. Build with :func:`packet_scene`.

    ``instances`` (default): every connected piece of the mesh (a tree, a cylinder, a wall)
    becomes an Embree instance of its own small scene, built in the piece's principal-axes
    frame. A slanted cylinder's triangles then sit in tight boxes (in world axes a long
    sliver's box is most of the cylinder's), and no leaf mixes pieces: frames 15-35 %
    faster on the scenario families, 3.3x in Random-Angle Cylinder
    (bench/bench_camera_families.py, docs/benchmarks.md). A mesh that falls apart into
    more than :data:`MAX_INSTANCES` pieces, or into pieces of fewer than
    :data:`MIN_PIECE_FACES` triangles on average (a triangle soup), is built as one scene.
    With instances the hit test runs on the ray mapped into the piece's frame (float32),
    so a ray through a shared edge or grazing a silhouette can report the
    neighbouring triangle or miss where the world-frame test hits: about 2 pixels in a
    million differ from the plain scene. False: one scene over all triangles, the same
    first hits as ``embreex``'s one-ray query."""

    def __init__(self, lib, device, vertices32: np.ndarray, faces: np.ndarray,
                 instances: bool = True):
        self._lib = lib
        self._subscenes: list[int] = []
        scene = lib.rtcNewScene(device)
        if not scene:
            raise OSError("rtcNewScene failed")
        self._scene = scene
        lib.rtcSetSceneFlags(scene, _SCENE_FLAG_ROBUST)
        v = np.ascontiguousarray(vertices32, dtype=np.float32)
        f = np.ascontiguousarray(faces, dtype=np.uint32)
        pieces = _pieces(f, len(v)) if instances else []
        if len(pieces) > MAX_INSTANCES or len(f) < MIN_PIECE_FACES * len(pieces):
            pieces = []  # a triangle soup, or too many pieces: one scene
        #: global face of (instance, primitive): face_of[offset[instance] + prim]; a hit
        #: outside any instance (instance id invalid) is the face itself
        if not pieces:
            self._attach_triangles(device, scene, v, f)
            self.face_of = np.zeros(0, np.int64)
            self.offset = np.zeros(1, np.int64)
        else:
            self.face_of = np.concatenate(pieces).astype(np.int64)
            self.offset = np.zeros(len(pieces), np.int64)
            at = 0
            for faces_k in pieces:
                used, local_f = np.unique(f[faces_k], return_inverse=True)
                gid = self._attach_instance(device, scene, v[used].astype(np.float64),
                                            local_f.reshape(-1, 3).astype(np.uint32))
                self.offset[gid] = at
                at += len(faces_k)
        lib.rtcCommitScene(scene)
        err = lib.rtcGetDeviceError(device)
        if err:
            raise OSError(f"Embree scene build failed (error {err})")

    def _attach_instance(self, device, scene, points: np.ndarray, faces: np.ndarray) -> int:
        """One piece (its vertices in world units, its faces indexing them) as an instance
        of a scene built in the piece's principal-axes frame; returns its id in ``scene``
        (the instance count so far)."""
        lib = self._lib
        centre, axes = _principal_frame(points)
        sub = lib.rtcNewScene(device)
        if not sub:
            raise OSError("rtcNewScene failed")
        self._subscenes.append(sub)
        lib.rtcSetSceneFlags(sub, _SCENE_FLAG_ROBUST)
        self._attach_triangles(device, sub, ((points - centre) @ axes).astype(np.float32), faces)
        lib.rtcCommitScene(sub)
        geom = lib.rtcNewGeometry(device, _GEOMETRY_TYPE_INSTANCE)
        if not geom:
            raise OSError("rtcNewGeometry (instance) failed")
        lib.rtcSetGeometryInstancedScene(geom, sub)
        # local -> world: the axes as the matrix's columns, then the translation
        xfm = np.concatenate([axes.T.ravel(), centre]).astype(np.float32)
        lib.rtcSetGeometryTransform(geom, 0, _FORMAT_FLOAT3X4_COLUMN_MAJOR, xfm.ctypes.data)
        lib.rtcCommitGeometry(geom)
        gid = lib.rtcAttachGeometry(scene, geom)
        lib.rtcReleaseGeometry(geom)
        if gid != len(self._subscenes) - 1:
            raise OSError(f"Embree numbered instance {len(self._subscenes) - 1} as {gid}")
        return int(gid)

    def _attach_triangles(self, device, scene, v: np.ndarray, f: np.ndarray) -> None:
        lib = self._lib
        geom = lib.rtcNewGeometry(device, _GEOMETRY_TYPE_TRIANGLE)
        if not geom:
            raise OSError("rtcNewGeometry failed")
        for kind, fmt, arr in ((_BUFFER_TYPE_VERTEX, _FORMAT_FLOAT3, v),
                               (_BUFFER_TYPE_INDEX, _FORMAT_UINT3, f)):
            ptr = lib.rtcSetNewGeometryBuffer(geom, kind, 0, fmt, 12, len(arr))
            if not ptr:
                lib.rtcReleaseGeometry(geom)
                raise OSError(f"rtcSetNewGeometryBuffer failed (Embree error "
                              f"{lib.rtcGetDeviceError(device)})")
            ctypes.memmove(ptr, arr.ctypes.data, arr.nbytes)
        lib.rtcCommitGeometry(geom)
        lib.rtcAttachGeometry(scene, geom)
        lib.rtcReleaseGeometry(geom)

    def __del__(self):
        scene, self._scene = getattr(self, "_scene", 0), 0
        if scene:
            self._lib.rtcReleaseScene(scene)
        for sub in getattr(self, "_subscenes", ()):
            self._lib.rtcReleaseScene(sub)
        self._subscenes = []

    def first_hits(self, org32: np.ndarray, dirs32: np.ndarray, tfar32: np.ndarray | None,
                   out: np.ndarray | None = None) -> np.ndarray:
        """Index of the first triangle each ray hits (-1: none) for float32 origins and
        directions (N, 3) in the scene's units; ``tfar32`` (N,) the rays' lengths (None:
        unbounded, as embreex's default 1e37)."""
        n = len(dirs32)
        if tfar32 is None:
            tfar32 = np.full(n, 1e37, np.float32)
        if out is None:
            out = np.empty(n, np.int64)
        buf, valid = _packet_buffers()
        _run16(self._scene, buf.view(np.float32), buf.view(np.uint32), buf.ctypes.data,
               valid.view(np.int32), valid.ctypes.data,
               np.ascontiguousarray(org32, np.float32), np.ascontiguousarray(dirs32, np.float32),
               np.ascontiguousarray(tfar32, np.float32), self.face_of, self.offset, out)
        return out

    def fan_lengths(self, dirs_local: np.ndarray, rot: np.ndarray, origin: np.ndarray,
                    shift: np.ndarray, scale: float, tfar32: np.ndarray | None,
                    normals: np.ndarray, plane_c: np.ndarray, grazing: float,
                    dirs_world: np.ndarray, out: np.ndarray) -> None:
        """Rays from one ``origin`` (world, float64) along ``rot @ dirs_local[k]``: their
        world directions into ``dirs_world`` (N, 3) and the float64 length to the hit
        triangle's plane into ``out`` (N,) (inf: no hit, or a grazing one), in one pass. The
        same arithmetic as rotating the rays, querying with their float32 copies (origin
        shifted by ``shift`` and scaled by ``scale``, the scene's units) and recomputing each
        length from the plane (``normals``, ``plane_c``), done separately."""
        buf, valid = _packet_buffers()
        n = len(dirs_local)
        if tfar32 is None:
            tfar32 = np.full(n, 1e37, np.float32)
        _fan16(self._scene, buf.view(np.float32), buf.view(np.uint32), buf.ctypes.data,
               valid.view(np.int32), valid.ctypes.data, dirs_local, rot, origin, shift,
               float(scale), tfar32, normals, plane_c, float(grazing), self.face_of,
               self.offset, dirs_world, out)


    def fans_lengths(self, dirs_local: np.ndarray, rots: np.ndarray, origins: np.ndarray,
                     shift: np.ndarray, scale: float, tfar32: np.ndarray | None,
                     normals: np.ndarray, plane_c: np.ndarray, grazing: float,
                     dirs_world: np.ndarray, out: np.ndarray) -> None:
        """:meth:`fan_lengths` for V origins at once, in one compiled call: fan v leaves
        ``origins[v]`` (V, 3) along ``rots[v] @ dirs_local[k]`` (rots (V, 3, 3)); world
        directions into ``dirs_world`` (V, N, 3), lengths into ``out`` (V, N). Fan v gets
        exactly what ``fan_lengths`` gives it alone."""
        buf, valid = _packet_buffers()
        n = len(dirs_local)
        if tfar32 is None:
            tfar32 = np.full(n, 1e37, np.float32)
        _fans16(self._scene, buf.view(np.float32), buf.view(np.uint32), buf.ctypes.data,
                valid.view(np.int32), valid.ctypes.data, dirs_local, rots, origins, shift,
                float(scale), tfar32, normals, plane_c, float(grazing), self.face_of,
                self.offset, dirs_world, out)


def _packet_buffers():
    """A 64-byte-aligned RTCRayHit16 and valid mask, fresh per call (no state shared
    between threads)."""
    raw = np.zeros(_PACKET_BYTES + 128, np.uint8)
    off = (-raw.ctypes.data) % 64
    return raw[off:off + _PACKET_BYTES - 64], raw[off + _PACKET_BYTES - 64:off + _PACKET_BYTES]


def _pieces(faces: np.ndarray, n_vertices: int) -> list[np.ndarray]:
    """The faces of each connected piece (faces sharing a vertex), in face order, pieces
    ordered by their first face."""

    f = faces.astype(np.int64)
    label = connected_component_labels(f[:, [0, 1, 1, 2]].reshape(-1, 2),
                                       node_count=n_vertices)
    face_label = label[f[:, 0]]
    order = np.argsort(face_label, kind="stable")
    groups = np.split(order, np.flatnonzero(np.diff(face_label[order])) + 1)
    groups.sort(key=lambda g: int(g[0]))
    return groups


def _principal_frame(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Centroid and a right-handed orthonormal basis (columns) along the points' principal
    axes; the world axes when those are no better (within 1 %: cheaper boxes are not
    worth a transform per ray)."""
    centre = points.mean(axis=0)
    d = points - centre
    if len(points) < 3:
        return centre, np.eye(3)
    _, _, vt = np.linalg.svd(d, full_matrices=False)
    axes = vt.T.copy()
    if np.linalg.det(axes) < 0.0:
        axes[:, 2] = -axes[:, 2]
    pad = 1e-3 * max(float(np.ptp(d, axis=0).max()), 1e-12)
    vol_world = np.prod(np.ptp(d, axis=0) + pad)
    vol_axes = np.prod(np.ptp(d @ axes, axis=0) + pad)
    if not vol_axes < 0.99 * vol_world:
        axes = np.eye(3)
    return centre, axes


def packet_scene(vertices32: np.ndarray, faces: np.ndarray,
                 instances: bool = True) -> PacketScene | None:
    """A :class:`PacketScene`, or None when Embree 4 cannot be loaded or built."""
    lib = _library()
    if lib is None:
        return None
    dev = _device(lib)
    if dev is None:
        return None
    try:
        scene = PacketScene(lib, dev, vertices32, faces, instances)
    except OSError:
        return None
    _compile(scene)
    return scene


_COMPILED = False


def _compile(scene: PacketScene) -> None:
    """Compile the kernels now (once per process; they call Embree through a ctypes
    pointer, which numba cannot cache on disk): ~2 s that would otherwise stall the first
    frame, e.g. of a bridge running in real time."""
    global _COMPILED
    if _COMPILED:
        return
    one = np.zeros((1, 3), np.float32)
    scene.first_hits(one, one, None)
    scene.fan_lengths(np.array([[0.0, 0.0, 1.0]]), np.eye(3), np.zeros(3), np.zeros(3), 1.0,
                      None, np.zeros((1, 3)), np.zeros(1), 1e-9, np.empty((1, 3)),
                      np.empty(1))
    _COMPILED = True


def _intersect16():
    lib = _library()
    return lib.rtcIntersect16


@njit(cache=True)
def plane_length(t, dirs_world, k, origin, normals, plane_c, grazing):
    """Length of ray k (unit ``dirs_world[k]`` from ``origin``) to triangle t's plane
    (float64); inf for a miss (t < 0) or a grazing hit."""
    if t < 0:
        return np.inf
    nd = (normals[t, 0] * dirs_world[k, 0] + normals[t, 1] * dirs_world[k, 1]
          + normals[t, 2] * dirs_world[k, 2])
    if not abs(nd) > grazing:
        return np.inf
    num = plane_c[t] - (normals[t, 0] * origin[0] + normals[t, 1] * origin[1]
                        + normals[t, 2] * origin[2])
    return num / nd


@njit
def _set_lane(bf, bu, lane, ox, oy, oz, dx, dy, dz, tfar):
    """One ray of the packet: origin, direction, [0, tfar], no hit yet."""
    bf[_OX + lane] = ox
    bf[_OY + lane] = oy
    bf[_OZ + lane] = oz
    bf[_TNEAR + lane] = 0.0
    bf[_DX + lane] = dx
    bf[_DY + lane] = dy
    bf[_DZ + lane] = dz
    bf[_TIME + lane] = 0.0
    bf[_TFAR + lane] = tfar
    bu[_MASK + lane] = _INVALID_ID
    bu[_ID + lane] = 0
    bu[_FLAGS + lane] = 0
    bu[_PRIM + lane] = _INVALID_ID
    bu[_GEOM + lane] = _INVALID_ID
    bu[_INST + lane] = _INVALID_ID


@njit
def _face(bu, lane, face_of, offset):
    """The mesh face a lane hit (-1: none)."""
    pid = bu[_PRIM + lane]
    if pid == _INVALID_ID:
        return np.int64(-1)
    inst = bu[_INST + lane]
    if inst == _INVALID_ID:
        return np.int64(pid)
    return face_of[offset[inst] + np.int64(pid)]


@njit
def _run16(scene, bf, bu, buf_addr, valid, valid_addr, org32, dirs32, tfar32, face_of, offset,
           out):
    """Runs of 16 consecutive rays per rtcIntersect16 call (a row segment of an image)."""
    n = dirs32.shape[0]
    for p in range(0, n, _W):
        m = min(_W, n - p)
        for lane in range(_W):
            valid[lane] = -1 if lane < m else 0
            if lane < m:
                k = p + lane
                _set_lane(bf, bu, lane, org32[k, 0], org32[k, 1], org32[k, 2], dirs32[k, 0],
                          dirs32[k, 1], dirs32[k, 2], tfar32[k])
        _RTC_INTERSECT16(valid_addr, scene, buf_addr, 0)
        for lane in range(m):
            out[p + lane] = _face(bu, lane, face_of, offset)

@njit
def _fan16(scene, bf, bu, buf_addr, valid, valid_addr, dirs_local, rot, origin, shift, scale,
           tfar32, normals, plane_c, grazing, face_of, offset, dirs_world, out):
    """PacketScene.fan_lengths: rotate, query 16 rays per call, plane length per ray."""
    n = dirs_local.shape[0]
    ox = np.float32((origin[0] - shift[0]) * scale)
    oy = np.float32((origin[1] - shift[1]) * scale)
    oz = np.float32((origin[2] - shift[2]) * scale)
    for p in range(0, n, _W):
        m = min(_W, n - p)
        for lane in range(_W):
            if lane < m:
                k = p + lane
                x, y, z = dirs_local[k, 0], dirs_local[k, 1], dirs_local[k, 2]
                for a in range(3):
                    dirs_world[k, a] = rot[a, 0] * x + rot[a, 1] * y + rot[a, 2] * z
                valid[lane] = -1
                _set_lane(bf, bu, lane, ox, oy, oz, np.float32(dirs_world[k, 0]),
                          np.float32(dirs_world[k, 1]), np.float32(dirs_world[k, 2]),
                          tfar32[k])
            else:
                valid[lane] = 0
        _RTC_INTERSECT16(valid_addr, scene, buf_addr, 0)
        for lane in range(m):
            out[p + lane] = plane_length(_face(bu, lane, face_of, offset), dirs_world, p + lane,
                                         origin, normals, plane_c, grazing)


@njit
def _fans16(scene, bf, bu, buf_addr, valid, valid_addr, dirs_local, rots, origins, shift,
            scale, tfar32, normals, plane_c, grazing, face_of, offset, dirs_world, out):
    """PacketScene.fans_lengths: _fan16 for each origin."""
    for v in range(origins.shape[0]):
        _fan16(scene, bf, bu, buf_addr, valid, valid_addr, dirs_local, rots[v], origins[v],
               shift, scale, tfar32, normals, plane_c, grazing, face_of, offset,
               dirs_world[v], out[v])


_RTC_INTERSECT16 = _intersect16() if _library() is not None else None
