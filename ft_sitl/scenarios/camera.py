"""Forward-facing depth camera: ray casting against the scenario's triangle mesh.

A pinhole depth camera rigidly mounted on the vehicle. Each frame casts one ray per pixel
from the camera centre against the scenario mesh (trimesh, with Intel Embree through the
``embreex`` package when importable) and returns

* ``depth``: an (H, W) float32 image of **z-depth** in metres, i.e. the distance along the
  optical axis (what a RealSense / stereo camera reports and what the planners' depth
  filters read), *not* the Euclidean length of the ray. Pixels with no surface within
  ``[min_range_m, max_range_m]``, and dropped-out pixels, are **NaN** (never 0 or inf);
* the point cloud of the valid pixels in the body frame (FLU, relative to the body origin,
  mount offset included) and in the world frame (ENU), with the frame's timestamp and the
  camera's pose.

Frames
------
Camera optical frame: x right, y down, z forward (OpenCV / ROS ``*_optical_frame``).
Pixel ``(u, v)`` = (column, row); integer coordinates are pixel *centres*, so a ray leaves
through ``x_n = (u - cx) / fx``, ``y_n = (v - cy) / fy`` and the principal point at the
image centre is ``cx = (width - 1) / 2``, ``cy = (height - 1) / 2``. A point at bearing
``b`` (radians, positive to the left, i.e. towards body +y) and level with the camera lands
in column ``u = cx - fx * tan(b)``, i.e. ``b = atan((cx - u) / fx)``.

Mount: optical z is body +x (forward) when ``mount_pitch_rad`` is 0; a positive
``mount_pitch_rad`` tilts the camera **down** (a right-handed rotation about body +y, the
left axis of FLU). ``mount_position_body`` is the camera centre in the body frame.

Defaults
--------
Modelled on the depth camera of the evaluated planners (EGO-Planner / Fast-Planner, whose
simulated and real setups use an Intel RealSense D435 depth stream): 640 x 480 pixels,
``fx = fy = 387.229248046875`` px (the value in the planners' ``grid_map`` configs), hence
about 79.2 x 63.6 deg field of view, 30 Hz. The planners' configs put the principal point at
(321.05, 243.45); here it is at the image centre. Range 0.2 m to 10 m: 0.2 m is the planners'
``depth_filter_mindist``; they cut far points themselves (``depth_filter_maxdist`` 5 m,
``max_ray_length`` ~4.5 m), so the camera hands them more than they use. Noise is off by
default.

Noise model (optional, stereo-like): Gaussian on z-depth with ``sigma = noise_k * z**2``
(stereo depth error grows with the square of the depth: ``sigma_z = z**2 * e / (f * B)``
for disparity error ``e`` px, focal length ``f`` px, baseline ``B`` m). ``NOISE_K_DEFAULT``
= 0.001 1/m (1 mm at 1 m, 4 mm at 2 m, 2.5 cm at 5 m) is the suggested value when enabled;
``stereo_noise_k`` gives the figure for a given stereo rig (D435 at 640 px, 50 mm baseline,
0.08 px subpixel: ~0.0041 1/m). Plus an independent per-pixel dropout probability. Both draw
only from the ``numpy.random.Generator`` passed to ``capture`` (never a global RNG); the
range cut applies to the *measured* (noisy) depth, so every finite depth lies in range.

Ray casting: the first triangle each ray hits (Embree, through trimesh's scaled scene,
queried directly with rays built in one compiled pass, 16 rays per call when Embree's C
API loads, each connected mesh piece an instance in its own principal-axes frame;
trimesh's wrapper re-normalised and converted every ray, which cost as much as
the query); the distance is then recomputed in
float64 from that triangle's plane. Measured on a 51k-triangle forest scene at 640 x 480,
this is ~2.3x faster than ``intersects_location(..., multiple_hits=False)`` and gives the
same float64 distances (to 1e-13 m). Without noise, each ray stops just past
``max_range_m`` (a surface beyond it is dropped anyway). See ``bench/bench_camera.py``:
~6.4 M rays/s for whole frames on one core.

The mesh must not be modified after the camera is built (its BVH and plane table are built
once in the constructor); build a new camera for a new mesh.

Benchmark cameras
-----------------
The cameras the navigators fly with are presets of this one (:func:`camera_config`):
"benchmark", 160 x 120 at :data:`BENCHMARK_CAMERA_HZ` (30 Hz), and "d435", the originals'
stream at 320 x 240 and 30 Hz, both with the field of view above and a 10 m range,
optionally resized or at another rate. :data:`CAMERA_PARAMS` declares the parameters every
camera-based navigator takes to choose one; :func:`camera_of` turns its settings into the
configuration.
"""

from __future__ import annotations

import math
import numbers
import warnings
from dataclasses import dataclass, field, replace

import numpy as np
import trimesh
from numba import njit

from ft_sitl.rotations import matrix_from_quat
from ft_sitl.scenarios.embree_packets import packet_scene, plane_length
from ft_sitl.scenarios.movers import image_first_hit, ray_first_hit
from ft_sitl.schema import Param, Schema

__all__ = [
    "NOISE_K_DEFAULT",
    "CameraConfig",
    "DepthCamera",
    "DepthFrame",
    "embree_available",
    "stereo_noise_k",
]

#: Suggested ``noise_k`` (1/m) when depth noise is enabled: sigma = 0.001 * z**2.
NOISE_K_DEFAULT = 0.001

#: Focal length (px) of the planners' 640 x 480 depth camera (RealSense D435 depth stream).
D435_FX_640 = 387.229248046875

# a hit whose ray is closer than this cosine to the triangle's plane is dropped (grazing)
_GRAZING_COS = 1e-9


def stereo_noise_k(fx_px: float, baseline_m: float, subpixel_px: float = 0.08) -> float:
    """``noise_k`` for a stereo rig: ``sigma_z = z**2 * subpixel / (fx * baseline)``.

    With the D435 at 640 px (fx 387.2 px, 50 mm baseline, 0.08 px subpixel RMS, Intel's
    figure for a well-textured scene) this gives ~0.0041 1/m.
    """
    if fx_px <= 0 or baseline_m <= 0 or subpixel_px < 0:
        raise ValueError("fx_px and baseline_m must be > 0 and subpixel_px >= 0")
    return subpixel_px / (fx_px * baseline_m)


def embree_available() -> bool:
    """Whether trimesh can use Embree (the ``embreex`` package imports)."""
    return bool(trimesh.ray.has_embree)


# --- configuration ----------------------------------------------------------------------------
@dataclass(frozen=True)
class CameraConfig:
    """Depth camera intrinsics, range, rate, noise and mount. Validated on construction.

    ``cx`` / ``cy`` default (None) to the image centre, ``(width - 1) / 2`` and
    ``(height - 1) / 2`` (pixel-centre convention, see the module docstring).
    """

    width: int = 640
    height: int = 480
    fx: float = D435_FX_640
    fy: float = D435_FX_640
    cx: float | None = None
    cy: float | None = None
    min_range_m: float = 0.2
    max_range_m: float = 10.0
    rate_hz: float = 30.0
    mount_position_body: tuple[float, float, float] = (0.0, 0.0, 0.0)
    mount_pitch_rad: float = 0.0
    noise_k: float = 0.0
    dropout: float = 0.0

    def __post_init__(self):
        # fill the principal point and freeze the mount as a tuple of floats
        if self.cx is None and isinstance(self.width, int):
            object.__setattr__(self, "cx", (self.width - 1) / 2.0)
        if self.cy is None and isinstance(self.height, int):
            object.__setattr__(self, "cy", (self.height - 1) / 2.0)
        try:
            mount = tuple(float(c) for c in np.asarray(self.mount_position_body).ravel())
        except (TypeError, ValueError):
            mount = ()
        object.__setattr__(self, "mount_position_body", mount)
        self.validate()

    def validate(self) -> None:
        """Raise ValueError naming the first offending field and its allowed range."""

        def finite(name: str) -> float:
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, numbers.Real) or not math.isfinite(v):
                raise ValueError(f"CameraConfig.{name} must be a finite number, got {v!r}")
            return float(v)

        for name in ("width", "height"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int | np.integer) or not 1 <= v <= 16384:
                raise ValueError(f"CameraConfig.{name} must be an integer in [1, 16384], "
                                 f"got {v!r}")
        for name in ("fx", "fy"):
            v = finite(name)
            if not v > 0.0:
                raise ValueError(f"CameraConfig.{name} must be > 0 (pixels), got {v!r}")
        for name, size in (("cx", self.width), ("cy", self.height)):
            v = finite(name)
            if not -0.5 <= v <= size - 0.5:
                raise ValueError(f"CameraConfig.{name} must be in [-0.5, {size - 0.5}] "
                                 f"(inside the image), got {v!r}")
        lo = finite("min_range_m")
        if lo < 0.0:
            raise ValueError(f"CameraConfig.min_range_m must be >= 0, got {lo!r}")
        hi = finite("max_range_m")
        if not hi > lo:
            raise ValueError(f"CameraConfig.max_range_m must be > min_range_m ({lo}) and "
                             f"finite, got {hi!r}")
        rate = finite("rate_hz")
        if not 0.0 < rate <= 1e6:
            raise ValueError(f"CameraConfig.rate_hz must be in (0, 1e6] Hz, got {rate!r}")
        m = self.mount_position_body
        if len(m) != 3 or not all(math.isfinite(c) for c in m):
            raise ValueError("CameraConfig.mount_position_body must be 3 finite numbers (m, "
                             f"body FLU), got {m!r}")
        pitch = finite("mount_pitch_rad")
        if not -math.pi / 2 <= pitch <= math.pi / 2:
            raise ValueError("CameraConfig.mount_pitch_rad must be in [-pi/2, pi/2] "
                             f"(positive = down), got {pitch!r}")
        k = finite("noise_k")
        if k < 0.0:
            raise ValueError(f"CameraConfig.noise_k must be >= 0 (1/m), got {k!r}")
        p = finite("dropout")
        if not 0.0 <= p < 1.0:
            raise ValueError(f"CameraConfig.dropout must be in [0, 1), got {p!r}")

    @property
    def fov_deg(self) -> tuple[float, float]:
        """(horizontal, vertical) field of view in degrees, edge to edge of the image."""
        h = math.atan((self.cx + 0.5) / self.fx) + math.atan((self.width - 0.5 - self.cx)
                                                             / self.fx)
        v = math.atan((self.cy + 0.5) / self.fy) + math.atan((self.height - 0.5 - self.cy)
                                                             / self.fy)
        return math.degrees(h), math.degrees(v)

    @property
    def period_us(self) -> float:
        """Frame period in microseconds (not rounded)."""
        return 1e6 / self.rate_hz

    @property
    def n_pixels(self) -> int:
        return self.width * self.height

    def subsampled(self, step: int) -> CameraConfig:
        """The same camera (field of view, range, rate, mount, noise) at 1/step resolution."""
        if isinstance(step, bool) or not isinstance(step, int) or step < 1:
            raise ValueError(f"step must be an integer >= 1, got {step!r}")
        if step > min(self.width, self.height):
            raise ValueError(f"step must be <= min(width, height) = "
                             f"{min(self.width, self.height)}, got {step}")
        return replace(self, width=self.width // step, height=self.height // step,
                       fx=self.fx / step, fy=self.fy / step,
                       cx=(self.cx + 0.5) / step - 0.5, cy=(self.cy + 0.5) / step - 0.5)


# --- the benchmark's cameras ------------------------------------------------------------------
#: the benchmark camera's frame rate (Hz): the originals' depth stream (protocol 3 on;
#: 15 Hz before, which trials of protocols 1 and 2 keep)
BENCHMARK_CAMERA_HZ = 30.0

CAMERA_PARAMS = Schema((
    Param("camera", "benchmark", choices=("benchmark", "d435"),
          doc="depth camera: 'benchmark' 160 x 120 @ 30 Hz, 'd435' the originals' "
              "320 x 240 @ 30 Hz (same field of view)"),
    Param("camera_width", None, "px", (16, 1280), kind="int",
          doc="frame width (none: the camera's)"),
    Param("camera_height", None, "px", (12, 960), kind="int",
          doc="frame height (none: the camera's)"),
    Param("camera_rate_hz", None, "Hz", (1.0, 60.0), kind="float",
          doc="frame rate (none: the camera's)"),
))
"""The depth camera's parameters, which every camera-based navigator takes."""


def camera_config(camera: str, width: int | None, height: int | None, rate_hz: float | None):
    """The planners' depth camera: "benchmark" (160 x 120 @ 30 Hz, the originals' frame
    rate) or "d435" (the originals' stream with every second pixel: 320 x 240 @ 30 Hz),
    optionally resized or at another rate (ranges: see :data:`CAMERA_PARAMS`)."""

    for key, value in (("camera", camera), ("camera_width", width),
                       ("camera_height", height), ("camera_rate_hz", rate_hz)):
        CAMERA_PARAMS[key].check(value, "depth camera")
    base = CameraConfig(max_range_m=10.0)
    if camera == "benchmark":
        cfg = replace(base.subsampled(4), rate_hz=BENCHMARK_CAMERA_HZ)
    else:
        cfg = replace(base.subsampled(2), rate_hz=30.0)
    if width is not None or height is not None:
        w = int(width or cfg.width)
        h = int(height or cfg.height)
        step_x = base.width / w
        cfg = replace(base, width=w, height=h, fx=base.fx / step_x, fy=base.fy / step_x,
                      cx=(w - 1) / 2.0, cy=(h - 1) / 2.0, rate_hz=cfg.rate_hz)
    if rate_hz is not None:
        cfg = replace(cfg, rate_hz=float(rate_hz))
    return cfg


def camera_of(settings: dict):
    """The depth camera a navigator's resolved settings name (:data:`CAMERA_PARAMS`)."""
    return camera_config(settings["camera"], settings["camera_width"],
                         settings["camera_height"], settings["camera_rate_hz"])


# --- output -----------------------------------------------------------------------------------
@dataclass
class DepthFrame:
    """One depth image and its point cloud.

    ``depth`` (H, W) float32: z-depth in metres, NaN where invalid. ``points_body`` /
    ``points_world`` (N, 3) float64: the valid pixels in row-major order, body FLU (relative
    to the body origin) and world ENU; ``pixels`` (N, 2) int32 their (row, col). The pose
    fields describe the vehicle and the camera at ``t_us``.
    """

    t_us: int
    depth: np.ndarray
    points_body: np.ndarray
    points_world: np.ndarray
    pixels: np.ndarray
    p_world_body: np.ndarray
    q_world_body: np.ndarray
    p_world_camera: np.ndarray
    #: rotation matrix taking optical-frame vectors (x right, y down, z forward) to world
    r_world_optical: np.ndarray = field(repr=False)

    @property
    def valid(self) -> np.ndarray:
        """(H, W) bool: pixels with a depth."""
        return np.isfinite(self.depth)

    def __getattr__(self, name: str):
        # DepthCamera.capture leaves the point clouds to the first reader (the planners'
        # maps read only the image): computed then, from the frame's float64 depths
        if name in _CLOUD_FIELDS:
            make = self.__dict__.pop("_make_cloud", None)
            if make is not None:
                self.__dict__.update(zip(_CLOUD_FIELDS, make()))
                return self.__dict__[name]
        raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")

    def __getstate__(self):  # pickling / copying: the clouds, not the function making them
        for name in _CLOUD_FIELDS:
            getattr(self, name)
        return self.__dict__


_CLOUD_FIELDS = ("points_body", "points_world", "pixels")


# --- camera -----------------------------------------------------------------------------------
def optical_to_body(mount_pitch_rad: float) -> np.ndarray:
    """Rotation optical (x right, y down, z forward) -> body FLU, camera pitched down."""
    # pitch 0: optical x -> -y_body, optical y -> -z_body, optical z -> +x_body
    r0 = np.array([[0.0, 0.0, 1.0],
                   [-1.0, 0.0, 0.0],
                   [0.0, -1.0, 0.0]])
    c, s = math.cos(mount_pitch_rad), math.sin(mount_pitch_rad)
    ry = np.array([[c, 0.0, s],
                   [0.0, 1.0, 0.0],
                   [-s, 0.0, c]])  # right-handed about body +y: tilts +x towards -z
    return ry @ r0


# --- kernels (one pass each over the pixels; the per-frame numpy glue cost as much as Embree) --
@njit(cache=True)
def _rotate_rays(dirs_optical, r_wo, origin, dirs_world, dirs32, org32, shift, scale):
    """World ray directions (float64 and Embree's float32) and Embree's scaled origins."""
    ox = np.float32((origin[0] - shift[0]) * scale)
    oy = np.float32((origin[1] - shift[1]) * scale)
    oz = np.float32((origin[2] - shift[2]) * scale)
    for k in range(dirs_optical.shape[0]):
        x, y, z = dirs_optical[k, 0], dirs_optical[k, 1], dirs_optical[k, 2]
        for a in range(3):
            d = r_wo[a, 0] * x + r_wo[a, 1] * y + r_wo[a, 2] * z
            dirs_world[k, a] = d
            dirs32[k, a] = d
        org32[k, 0] = ox
        org32[k, 1] = oy
        org32[k, 2] = oz


@njit(cache=True)
def _hit_lengths(tri, dirs_world, origin, normals, plane_c, grazing, out):
    """Ray length to the hit triangle's plane (float64); inf on a miss or a grazing hit."""
    for k in range(tri.shape[0]):
        out[k] = plane_length(tri[k], dirs_world, k, origin, normals, plane_c, grazing)


@njit(cache=True)
def _depth_image(z, lo, hi, depth):
    """The float32 depth image (NaN outside [lo, hi]); returns the number of valid pixels."""
    n = 0
    for k in range(z.shape[0]):
        zk = z[k]
        if not (zk >= lo and zk <= hi):
            depth[k] = np.nan
            continue
        depth[k] = np.float32(zk)
        n += 1
    return n


@njit(cache=True)
def _cloud(z, lo, hi, width, rays_z1, r_bo, mount, r_wb, p_wb, pb, pw, pix):
    """The valid pixels' points (body and world) and (row, col), from the float64 depths."""
    n = 0
    for k in range(z.shape[0]):
        zk = z[k]
        if not (zk >= lo and zk <= hi):
            continue
        x, y, w = rays_z1[k, 0] * zk, rays_z1[k, 1] * zk, rays_z1[k, 2] * zk
        for a in range(3):
            pb[n, a] = r_bo[a, 0] * x + r_bo[a, 1] * y + r_bo[a, 2] * w + mount[a]
        for a in range(3):
            pw[n, a] = r_wb[a, 0] * pb[n, 0] + r_wb[a, 1] * pb[n, 1] + r_wb[a, 2] * pb[n, 2] \
                + p_wb[a]
        pix[n, 0] = k // width
        pix[n, 1] = k % width
        n += 1
    return n


class DepthCamera:
    """A depth camera casting rays against ``mesh`` (a ``trimesh.Trimesh``, world ENU).

    ``config`` None means the defaults. Builds the intersector once (Embree when ``embreex``
    imports, else trimesh's pure-numpy triangle intersector, with a warning: same results,
    far slower). Embree's BVH build may use worker threads; its ray queries run on the
    calling thread. ``packets`` (default) queries Embree 16 rays per call through its C API
    (:mod:`ft_sitl.scenarios.embree_packets`): the same first-hit triangles as ``embreex``'s
    one-ray-per-call query, ~1.3x faster; False, or when that library cannot be loaded,
    uses ``embreex``. ``instances`` (default, with packets): each connected piece of the
    mesh is an Embree instance in its own principal-axes frame, frames 15-35 % faster on
    the scenario families (3.3x with slanted cylinders); about 2 pixels in a million
    (rays through an edge or grazing a silhouette) then differ from the one-scene query
    (:class:`~ft_sitl.scenarios.embree_packets.PacketScene`).
    """

    def __init__(self, config: CameraConfig | None, mesh: trimesh.Trimesh, *,
                 packets: bool = True, instances: bool = True):
        if not isinstance(mesh, trimesh.Trimesh):
            raise TypeError(f"mesh must be a trimesh.Trimesh, got {type(mesh).__name__}")
        self.config = config = CameraConfig() if config is None else config
        config.validate()
        self.mesh = mesh
        h, w = config.height, config.width

        # per-pixel rays in the optical frame
        u = np.arange(w, dtype=np.float64)
        v = np.arange(h, dtype=np.float64)
        xn = np.broadcast_to((u - config.cx) / config.fx, (h, w))
        yn = np.broadcast_to(((v - config.cy) / config.fy)[:, None], (h, w))
        #: (H*W, 3) rays with unit z: (x_n, y_n, 1); a point at z-depth z is z * ray
        self.rays_z1 = np.stack([xn, yn, np.ones((h, w))], axis=-1).reshape(-1, 3)
        norm = np.linalg.norm(self.rays_z1, axis=1)
        #: (H*W, 3) unit ray directions in the optical frame, row-major pixels
        self.dirs_optical = self.rays_z1 / norm[:, None]
        #: (H*W,) z component of the unit rays: z-depth = ray length * cos_axis
        self.cos_axis = 1.0 / norm
        #: rotation optical -> body and the camera centre in the body frame
        self.r_body_optical = optical_to_body(config.mount_pitch_rad)
        self.mount_body = np.array(config.mount_position_body, dtype=np.float64)

        # unit face normals and plane offsets (own, from the vertices: robust to supplied
        # normals), for the float64 distance to the hit triangle's plane
        tri = np.asarray(mesh.triangles, dtype=np.float64)
        if len(tri) == 0:
            raise ValueError("the scenario mesh has no triangles")
        nrm = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        nlen = np.linalg.norm(nrm, axis=1)
        nrm = np.divide(nrm, nlen[:, None], out=np.zeros_like(nrm), where=nlen[:, None] > 0)
        self._normals = nrm
        self._plane_c = np.einsum("ij,ij->i", nrm, tri[:, 0])

        self.uses_embree = embree_available()
        if self.uses_embree:
            # Embree/trimesh ray back ends: loaded only when a depth camera is built
            from trimesh.ray import ray_pyembree

            self._intersector = ray_pyembree.RayMeshIntersector(mesh)
        else:
            warnings.warn("embreex is not importable: the depth camera falls back to trimesh's "
                          "triangle intersector (same results, orders of magnitude slower); "
                          "install embreex", RuntimeWarning, stacklevel=2)
            # Embree/trimesh ray back ends: loaded only when a depth camera is built
            from trimesh.ray import ray_triangle

            self._intersector = ray_triangle.RayMeshIntersector(mesh)
        self._tfar32 = None
        #: trimesh's scaled Embree scene (None without Embree), fetched once: trimesh's
        #: cached property re-hashes the mesh on every access
        self._wrap = self._intersector._scene if self.uses_embree else None
        #: the same scene queried in packets of 16 rays (None: embreex's single rays)
        self._packets = None
        if self.uses_embree:
            wrap = self._wrap
            scale = float(wrap.scale)
            self._tfar32 = (config.max_range_m / self.cos_axis * scale * 1.001 + 1e-6).astype(
                np.float32)
            if packets:

                v32 = ((np.array(mesh.vertices, dtype=np.float64) - wrap.origin)
                       * wrap.scale).astype(np.float32)
                self._packets = packet_scene(v32, np.asarray(mesh.faces), instances)
        if self._packets is None:  # build the BVH now rather than in the first frame
            self._intersector.intersects_first(np.zeros((1, 3)), np.array([[0.0, 0.0, 1.0]]))

        self._t0_us: int | None = None
        self.last_capture_us: int | None = None
        self.next_due_us: int | None = None

    # -- rate ----------------------------------------------------------------------------------
    def due(self, t_us: int) -> bool:
        """Whether a frame is due at ``t_us``: always before the first capture, then once per
        period on a grid anchored at the first capture (no drift: frame k is due at
        ``t0 + ceil(k * 1e6 / rate_hz)`` us, so 30 Hz stepped at 1 kHz gives 30 frames/s)."""
        return self.next_due_us is None or int(t_us) >= self.next_due_us

    def reset(self) -> None:
        """Forget the capture schedule (the next ``due`` is True)."""
        self._t0_us = self.last_capture_us = self.next_due_us = None

    def _schedule(self, t_us: int) -> None:
        if self._t0_us is None or t_us < self._t0_us:
            self._t0_us = t_us
        period = self.config.period_us
        k = math.floor((t_us - self._t0_us) / period + 1e-9)  # this frame's slot on the grid
        self.last_capture_us = t_us
        self.next_due_us = self._t0_us + math.ceil((k + 1) * period - 1e-6)

    # -- capture -------------------------------------------------------------------------------
    def _embree(self):
        """trimesh's scaled Embree scene (queried directly: its wrapper re-normalises and
        converts every ray, which cost as much as the query), or None without Embree."""
        return self._wrap

    def _first_hits(self, origin: np.ndarray, dirs_world: np.ndarray, dirs32, org32,
                    tfar32=None):
        """Index of the first triangle each ray hits (-1: none); with Embree, ``tfar32``
        limits each ray's length (scaled units)."""
        wrap = self._embree()
        if wrap is None:
            return self._intersector.intersects_first(
                np.broadcast_to(origin, dirs_world.shape), dirs_world)
        if self._packets is not None:
            return self._packets.first_hits(org32, dirs32, tfar32)
        if tfar32 is None:
            return wrap.scene.run(org32, dirs32)
        return wrap.scene.run(org32, dirs32, dists=tfar32.copy())

    def cast(self, origin_world: np.ndarray, dirs_world: np.ndarray, *, movers=None,
             movers_time_us: int | None = None,
             movers_range_m: float = np.inf) -> np.ndarray:
        """Ray length to the first hit for unit ``dirs_world`` (N, 3) from one origin (3,);
        inf where nothing is hit. float64, recomputed from the hit triangle's plane.
        ``movers`` are hit where they are at ``movers_time_us`` (those farther than
        ``movers_range_m`` are skipped)."""
        origin = np.ascontiguousarray(origin_world, dtype=np.float64).reshape(3)
        dirs = np.ascontiguousarray(dirs_world, dtype=np.float64)
        if dirs.ndim != 2 or dirs.shape[1] != 3:
            raise ValueError(f"dirs_world must have shape (N, 3), got {dirs.shape}")
        dirs32, org32 = self._embree_rays(origin, dirs.shape[0])
        if dirs32 is not None:
            dirs32[:] = dirs
        out = self._lengths(origin, dirs, dirs32, org32)
        if movers is not None and movers.count:
            ray_first_hit(movers.kind, movers.dims, movers.bounding,
                          movers.poses(movers_time_us), origin, dirs, out,
                          float(movers_range_m))
        return out

    def _embree_rays(self, origin: np.ndarray, n: int):
        wrap = self._embree()
        if wrap is None:
            return None, None
        org32 = np.empty((n, 3), np.float32)
        org32[:] = ((origin - wrap.origin) * wrap.scale).astype(np.float32)
        return np.empty((n, 3), np.float32), org32

    def _lengths(self, origin, dirs_world, dirs32, org32, tfar32=None) -> np.ndarray:
        tri = np.ascontiguousarray(
            self._first_hits(origin, dirs_world, dirs32, org32, tfar32), dtype=np.int64)
        out = np.empty(len(dirs_world))
        _hit_lengths(tri, dirs_world, origin, self._normals, self._plane_c, _GRAZING_COS, out)
        return out

    # -- many vehicles at once -----------------------------------------------------------------
    def cast_fans(self, origins_world: np.ndarray, rots: np.ndarray, dirs_local: np.ndarray,
                  *, max_range_m: float | None = None, movers=None,
                  movers_time_us: int | None = None) -> np.ndarray:
        """Ray lengths (V, N) of V fans of the same rays: fan v leaves ``origins_world[v]``
        (V, 3) along ``rots[v] @ dirs_local[k]`` (``rots`` (V, 3, 3), ``dirs_local`` (N, 3)
        unit vectors); inf where nothing is hit. With ``max_range_m`` a surface farther than
        that may be reported as inf (the rays stop just past it). ``movers`` are hit where
        they are at ``movers_time_us``. One compiled call for all the fans (Embree's packets);
        fan v's lengths are :meth:`cast`'s for its origin and the directions ``rots[v] @
        dirs_local[k]`` (rotated component by component: a matmul's may differ in the last
        bit)."""
        origins = np.ascontiguousarray(origins_world, dtype=np.float64)
        rots = np.ascontiguousarray(rots, dtype=np.float64)
        dirs_local = np.ascontiguousarray(dirs_local, dtype=np.float64)
        if origins.ndim != 2 or origins.shape[1] != 3 or rots.shape != (len(origins), 3, 3):
            raise ValueError(f"origins_world (V, 3) and rots (V, 3, 3) expected, got "
                             f"{origins.shape} and {rots.shape}")
        if dirs_local.ndim != 2 or dirs_local.shape[1] != 3:
            raise ValueError(f"dirs_local must have shape (N, 3), got {dirs_local.shape}")
        n_fans, n = len(origins), len(dirs_local)
        out = np.empty((n_fans, n))
        dirs_world = np.empty((n_fans, n, 3))
        if self._packets is not None:
            wrap = self._wrap
            tfar32 = None
            if max_range_m is not None:
                tfar32 = np.full(n, max_range_m * float(wrap.scale) * 1.001 + 1e-6, np.float32)
            self._packets.fans_lengths(dirs_local, rots, origins,
                                       np.asarray(wrap.origin, np.float64).reshape(3),
                                       float(wrap.scale), tfar32, self._normals, self._plane_c,
                                       _GRAZING_COS, dirs_world, out)
        else:  # one cast per fan
            for v in range(n_fans):
                np.matmul(dirs_local, rots[v].T, out=dirs_world[v])
                out[v] = self.cast(origins[v], dirs_world[v])
        if movers is not None and movers.count:
            if movers_time_us is None:
                raise ValueError("movers: pass movers_time_us, the simulation time to "
                                 "render them at")
            poses = movers.poses(movers_time_us)
            for v in range(n_fans):
                ray_first_hit(movers.kind, movers.dims, movers.bounding, poses, origins[v],
                              dirs_world[v], out[v], np.inf)
        return out

    def capture_depths(self, p_world: np.ndarray, q_world_body: np.ndarray, *, movers=None,
                       movers_time_us: int | None = None) -> np.ndarray:
        """The depth images (V, H, W) float32 of V vehicles at ``p_world`` (V, 3) with
        attitudes ``q_world_body`` (V, 4), in one compiled call (Embree's packets): image v
        is exactly :meth:`capture`'s ``depth`` for that pose. Noise-free cameras only (a
        noisy one needs :meth:`capture`'s generator per frame); no point clouds, and the
        capture schedule (:meth:`due`) is left alone."""
        cfg = self.config
        if cfg.noise_k > 0.0 or cfg.dropout > 0.0:
            raise ValueError("capture_depths renders noise-free frames: this camera has "
                             "noise_k or dropout set (use capture, with its rng)")
        p = np.ascontiguousarray(p_world, dtype=np.float64)
        q = np.asarray(q_world_body, dtype=np.float64)
        if p.ndim != 2 or p.shape[1] != 3 or q.shape != (len(p), 4):
            raise ValueError(f"p_world (V, 3) and q_world_body (V, 4) expected, got {p.shape} "
                             f"and {q.shape}")
        n_v, n_pix = len(p), cfg.n_pixels
        r_wo = np.empty((n_v, 3, 3))
        origins = np.empty((n_v, 3))
        for v in range(n_v):
            r_wb = matrix_from_quat(q[v], name="q_world_body")
            r_wo[v] = r_wb @ self.r_body_optical
            origins[v] = p[v] + r_wb @ self.mount_body
        lengths = np.empty((n_v, n_pix))
        dirs_world = np.empty((n_v, n_pix, 3))
        if self._packets is not None:
            wrap = self._wrap
            self._packets.fans_lengths(self.dirs_optical, r_wo, origins,
                                       np.asarray(wrap.origin, np.float64).reshape(3),
                                       float(wrap.scale), self._tfar32, self._normals,
                                       self._plane_c, _GRAZING_COS, dirs_world, lengths)
        else:  # one cast per vehicle
            for v in range(n_v):
                np.matmul(self.dirs_optical, r_wo[v].T, out=dirs_world[v])
                lengths[v] = self.cast(origins[v], dirs_world[v])
        depth = np.empty((n_v, n_pix), dtype=np.float32)
        lo, hi = float(cfg.min_range_m), float(cfg.max_range_m)
        poses = None
        if movers is not None and movers.count:
            if movers_time_us is None:
                raise ValueError("movers: pass movers_time_us, the simulation time to "
                                 "render them at")
            poses = movers.poses(movers_time_us)
        for v in range(n_v):
            z = lengths[v] * self.cos_axis
            if poses is not None:
                image_first_hit(movers.kind, movers.dims, movers.bounding, poses, origins[v],
                                r_wo[v], dirs_world[v], self.cos_axis, cfg.width, cfg.height,
                                cfg.fx, cfg.fy, cfg.cx, cfg.cy, lo, hi, z)
            _depth_image(z, lo, hi, depth[v])
        return depth.reshape(n_v, cfg.height, cfg.width)

    def capture(self, t_us: int, p_world, q_world_body,
                rng: np.random.Generator | None = None, *, movers=None,
                movers_time_us: int | None = None) -> DepthFrame:
        """Render one frame with the vehicle at ``p_world`` (3,), attitude ``q_world_body``.

        ``rng`` is required when ``noise_k`` or ``dropout`` is non-zero. ``movers`` (a
        :class:`~ft_sitl.scenarios.movers.Movers`) are rendered where they are at
        simulation time ``movers_time_us``: exact ray-primitive hits in float64, tested
        only on the pixels of each mover's projected bounding sphere. Updates the
        schedule used by ``due``.
        """
        cfg = self.config
        noisy = cfg.noise_k > 0.0 or cfg.dropout > 0.0
        if noisy and not isinstance(rng, np.random.Generator):
            raise ValueError("noise_k or dropout is set: pass rng=numpy.random.Generator "
                             "(the camera never uses a global RNG)")
        t_us = int(t_us)
        p_wb = np.asarray(p_world, dtype=np.float64).reshape(3)
        r_wb = matrix_from_quat(q_world_body, name="q_world_body")
        r_wo = r_wb @ self.r_body_optical
        origin = p_wb + r_wb @ self.mount_body

        n_pix = cfg.n_pixels
        dirs_world = np.empty((n_pix, 3))
        wrap = self._embree()
        # without noise a surface beyond max_range is dropped anyway: Embree stops the ray
        # just past it (0.1 % margin), which saves traversal in open scenes
        if self._packets is not None:  # rotation, query and plane lengths in one pass
            length = np.empty(n_pix)
            self._packets.fan_lengths(self.dirs_optical, r_wo, origin,
                                      np.asarray(wrap.origin, np.float64).reshape(3),
                                      float(wrap.scale), None if noisy else self._tfar32,
                                      self._normals, self._plane_c, _GRAZING_COS, dirs_world,
                                      length)
            z = length * self.cos_axis
        elif wrap is not None:
            dirs32, org32 = np.empty((n_pix, 3), np.float32), np.empty((n_pix, 3), np.float32)
            _rotate_rays(self.dirs_optical, r_wo, origin, dirs_world, dirs32, org32,
                         np.asarray(wrap.origin, np.float64).reshape(3), float(wrap.scale))
            z = self._lengths(origin, dirs_world, dirs32, org32,
                              None if noisy else self._tfar32) * self.cos_axis
        else:
            np.matmul(self.dirs_optical, r_wo.T, out=dirs_world)
            z = self._lengths(origin, dirs_world, None, None) * self.cos_axis
        if movers is not None and movers.count:
            if movers_time_us is None:
                raise ValueError("movers: pass movers_time_us, the simulation time to "
                                 "render them at")
            image_first_hit(movers.kind, movers.dims, movers.bounding,
                            movers.poses(movers_time_us), origin, r_wo, dirs_world,
                            self.cos_axis, cfg.width, cfg.height, cfg.fx, cfg.fy, cfg.cx,
                            cfg.cy, float(cfg.min_range_m), float(cfg.max_range_m), z)

        if noisy:
            valid = np.isfinite(z)
            idx = np.flatnonzero(valid)
            if cfg.noise_k > 0.0:
                zi = z[idx]
                z[idx] = zi + rng.standard_normal(idx.size) * (cfg.noise_k * zi * zi)
            if cfg.dropout > 0.0:
                z[idx[rng.random(idx.size) < cfg.dropout]] = np.inf

        depth = np.empty(n_pix, dtype=np.float32)
        lo, hi = float(cfg.min_range_m), float(cfg.max_range_m)
        n = _depth_image(z, lo, hi, depth)

        def make_cloud():
            pb, pw = np.empty((n, 3)), np.empty((n, 3))
            pix = np.empty((n, 2), np.int32)
            _cloud(z, lo, hi, cfg.width, self.rays_z1, self.r_body_optical, self.mount_body,
                   r_wb, p_wb, pb, pw, pix)
            return pb, pw, pix

        self._schedule(t_us)
        qn = np.asarray(q_world_body, dtype=np.float64)
        frame = DepthFrame.__new__(DepthFrame)  # the clouds on first access (__getattr__)
        frame.__dict__.update(
            t_us=t_us,
            depth=depth.reshape(cfg.height, cfg.width),
            p_world_body=p_wb.copy(),
            q_world_body=qn / np.linalg.norm(qn),
            p_world_camera=origin,
            r_world_optical=r_wo,
            _make_cloud=make_cloud,
        )
        return frame
