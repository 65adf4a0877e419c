"""NavRL's onboard dynamic-obstacle detector and tracker, working from the depth frames.

Our re-implementation of the perception the released NavRL deployment feeds its policy's
dynamic-obstacle input, its safety shield and its map's free regions with: the
``onboard_detector`` package's ``dynamicDetector`` (Zhefan-Xu/NavRL,
``ros2/onboard_detector/include/onboard_detector/dynamicDetector.cpp``, parameters
``ros2/onboard_detector/cfg/dynamic_detector_param.yaml``; the ROS 1 copy is the same
algorithm). :meth:`DynamicObstacleTracker.update` does, for each depth frame, what the
original's detection, tracking and classification timers do once per frame period:

1. **Points.** Every pixel (the image border of ``margin_px`` skipped) with a z-depth in
   [0.5, 5] m becomes a world point; points outside the +-5 m box around the camera or
   below ``ground_height_m`` (0.1 m) are dropped; a voxel filter (0.1 m) keeps one point
   per voxel that ``voxel_min_points`` points fall in (the one that completes the count).
2. **Clusters.** DBSCAN on those points: neighbours within ``dbscan_eps_m`` (the original
   compares the *squared* distance with its ``epsilon`` 0.1, so the radius is
   sqrt(0.1) = 0.316 m), core points with at least 20 neighbours (themselves included).
   Each cluster gives an axis-aligned box (horizontal sides at least 0.1 m), its point
   count and the standard deviation of its points.
3. **Association.** Each box is compared with each track's last box moved on by its
   velocity: the cosine similarity of a weighted feature (position relative to the camera
   x2, size, point count x0.5, point spread x0.5) must exceed 0.02 and the boxes must
   overlap (3-D IoU > 0); the most similar such track continues (a track two boxes pick is
   continued by both). A dynamic track nothing picks is predicted on at constant velocity
   for up to 20 frames ("estimated") and can be re-taken by a box (similarity > 0.015).
4. **Kalman filter** per track, on (x, y, vx, vy, ax, ay) with a constant-acceleration
   model (the original's ``kalmanFilterMatrixAcc``; its constant-velocity variant is not
   used): P0 = 0.25 I, Q = diag(0.01, 0.01, 0.05, 0.05, 0.05, 0.05), R = diag(0.04, 0.04,
   0.3, 0.3, 0.6, 0.6); the measurement is the box centre and the velocity and
   acceleration differenced over the last min(10, history) frames. Heights and sizes come
   from the box; after 10 frames a size within 40 % of the previous one keeps the previous.
5. **Classification.** A track is dynamic when (a) at least 10 of its 30 frames before this
   one were, or (b) for 5 frames in a row its points voted: each point of the current
   cluster that the camera saw ``frame_skip`` (5) frames ago gets its nearest point in the
   cluster of then (within 2 m); its horizontal displacement per time is its velocity; a
   point moving against the box's displacement is skipped, the others vote "moving" above
   0.15 m/s; at least 80 % must vote, fewer than half may be skipped, and the filter's
   speed must reach 0.15 m/s. Estimated tracks stay dynamic (their box is centred between
   the prediction and the last detection and grows by the distance, at most 1.5x).
   Dynamic boxes must be person-sized: within (0.8, 0.8, 1.0) m of (0.5, 0.5, 1.5) m
   (``constrain_size``: the original's target object size).
6. **Output** (:meth:`DynamicObstacleTracker.obstacles`): the dynamic boxes (centre,
   velocity (vx, vy, 0), size), and :func:`in_range` selects those within a horizontal
   distance, nearest first, as the original's ``get_dynamic_obstacles`` service does.

Differences, and why:

* the U-depth detector, whose boxes must confirm DBSCAN's (mutual best IoU > 0.05, merged
  to the larger box), and the YOLO person detector on the colour image (a person is dynamic
  at once) are left out: the benchmark renders no colour image, and the U-depth map is a
  second detector of the same obstacles;
* time steps are the frames' own timestamps (the original assumes one frame every
  ``time_step`` 0.033 s: from protocol 6 on the navigator gets the map's 20 Hz frames, which
  are 33 and 67 ms apart);
* the original's pose history holds 5 poses and is read at index 5 (past its end), and the
  association feature of a track takes the point count and spread of the *current*
  cluster with the same index; here the pose of 5 frames ago and the track's own cluster;
* the field of view a point must have been in is the camera's (the original's is fixed at
  +-42 x +-28 deg, a RealSense's);
* a predicted box reports the track's velocity (the original's leaves it unset);
* the camera-specific counts are scaled to the camera (:meth:`DetectorConfig.for_camera`):
  the border margin (10 px at 640 px) and the voxel filter's count (5 points at the
  original's ray density, 640 x 480 with every second pixel, fx 386 px; 1 at the benchmark
  camera's 160 x 120).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field, replace

import numpy as np
from numba import njit
from scipy.spatial import cKDTree

from ft_sitl.navigation.base import ObstacleStates
from ft_sitl.scenarios.camera import CameraConfig, DepthFrame

__all__ = ["DetectorConfig", "DynamicObstacleTracker", "dbscan", "dbscan_labels", "in_range"]

#: the original's depth camera: 640 px wide, fx 386.2 px, every second pixel used
ORIGINAL_WIDTH_PX = 640
ORIGINAL_FX_PX = 386.22674560546875
ORIGINAL_SKIP_PX = 2
ORIGINAL_MARGIN_PX = 10
ORIGINAL_VOXEL_MIN_POINTS = 5


@dataclass(frozen=True)
class DetectorConfig:
    """The detector's parameters; defaults from the released ROS 2
    ``dynamic_detector_param.yaml`` (the ROS 1 PX4 configuration differs in
    ``voxel_occupied_thresh`` 15, ``dynamic_consistency_threshold`` 20 and a 1.7 m tall
    target size). Counts of frames are frames of the depth stream."""

    margin_px: int = ORIGINAL_MARGIN_PX  # depth_filter_margin
    depth_min_m: float = 0.5  # depth_min_value
    depth_max_m: float = 5.0  # depth_max_value and raycast_max_length
    ground_height_m: float = 0.1  # ground_height
    local_range_m: float = 5.0  # localSensorRange (each axis, around the camera)
    voxel_m: float = 0.1  # the voxel filter's resolution
    voxel_min_points: int = ORIGINAL_VOXEL_MIN_POINTS  # voxel_occupied_thresh
    dbscan_eps_m: float = math.sqrt(0.1)  # dbscan_search_range_epsilon, squared there
    dbscan_min_points: int = 20  # dbscan_min_points_cluster
    history_size: int = 100  # history_size
    prediction_size: int = 20  # prediction_size
    similarity_threshold: float = 0.02  # similarity_threshold
    retrack_similarity_threshold: float = 0.015  # retrack_similarity_threshold
    fix_size_history: int = 10  # fix_size_history_threshold
    fix_size_ratio: float = 0.4  # fix_size_dimension_threshold
    kf_p: float = 0.25  # e_p
    kf_q: tuple[float, float, float] = (0.01, 0.05, 0.05)  # e_q_pos, e_q_vel, e_q_acc
    kf_r: tuple[float, float, float] = (0.04, 0.3, 0.6)  # e_r_pos, e_r_vel, e_r_acc
    kf_average_frames: int = 10  # kalman_filter_averaging_frames
    frame_skip: int = 5  # frame_skip
    dynamic_speed_m_s: float = 0.15  # dynamic_velocity_threshold
    dynamic_vote_ratio: float = 0.8  # dynamic_voting_threshold
    max_skip_ratio: float = 0.5  # maximum_skip_ratio
    force_dynamic_frames: int = 10  # frames_force_dynamic
    force_dynamic_range: int = 30  # frames_force_dynamic_check_range
    dynamic_consistency: int = 5  # dynamic_consistency_threshold
    constrain_size: bool = True  # constrain_size
    target_sizes: tuple = ((0.5, 0.5, 1.5),)  # target_object_size
    size_tolerance_m: tuple[float, float, float] = (0.8, 0.8, 1.0)  # hard-coded there
    nearest_max_m: float = 2.0  # hard-coded: nearest-neighbour search radius
    half_fov_rad: tuple[float, float] = (math.radians(42.0), math.radians(28.0))

    @classmethod
    def for_camera(cls, camera: CameraConfig, **overrides) -> DetectorConfig:
        """The defaults for ``camera`` (a frame already at the resolution the detector
        uses): the border margin scaled with the width, the voxel filter's count with the
        pixel density (fx squared) relative to the original's every-second-pixel stream,
        and the camera's half field of view."""
        hfov, vfov = camera.fov_deg
        density = (camera.fx / (ORIGINAL_FX_PX / ORIGINAL_SKIP_PX)) ** 2
        cfg = cls(margin_px=int(round(ORIGINAL_MARGIN_PX * camera.width / ORIGINAL_WIDTH_PX)),
                  voxel_min_points=max(1, int(round(ORIGINAL_VOXEL_MIN_POINTS * density))),
                  half_fov_rad=(math.radians(hfov / 2), math.radians(vfov / 2)))
        return replace(cfg, **overrides)


# --- points and clusters ---------------------------------------------------------------------

@njit(cache=True)
def _filtered_points(depth, fx, fy, cx, cy, r, cam, margin, dmin, dmax, ground, rng, res,
                     min_points, counts, touched, out):
    """Depth pixels -> world points, range and ground cuts, voxel filter (one point per
    voxel of the +-rng box around the camera, the min_points-th that falls in it).
    ``counts`` (n^3,) is all zero on entry and on return. Returns the number of points."""
    h, w = depth.shape
    n_ax = counts.shape[0]
    n_side = int(round(2.0 * rng / res))
    nt = 0
    m = 0
    for v in range(margin, h - margin):
        for u in range(margin, w - margin):
            z = np.float64(depth[v, u])
            if not (z >= dmin and z <= dmax):  # NaN too: no return
                continue
            px = (u - cx) * z / fx
            py = (v - cy) * z / fy
            wx = cam[0] + r[0, 0] * px + r[0, 1] * py + r[0, 2] * z
            wy = cam[1] + r[1, 0] * px + r[1, 1] * py + r[1, 2] * z
            wz = cam[2] + r[2, 0] * px + r[2, 1] * py + r[2, 2] * z
            if wz < ground:
                continue
            ix = int(math.floor((wx - cam[0] + rng) / res))
            iy = int(math.floor((wy - cam[1] + rng) / res))
            iz = int(math.floor((wz - cam[2] + rng) / res))
            if ix < 0 or iy < 0 or iz < 0 or ix >= n_side or iy >= n_side or iz >= n_side:
                continue
            k = (ix * n_side + iy) * n_side + iz
            if k >= n_ax:
                continue
            if counts[k] == 0:
                touched[nt] = k
                nt += 1
            counts[k] += 1
            if counts[k] == min_points:
                out[m, 0], out[m, 1], out[m, 2] = wx, wy, wz
                m += 1
    for i in range(nt):
        counts[touched[i]] = 0
    return m


@njit(cache=True)
def _neighbours(i, points, cell, dims, sorted_cells, order, eps2, out, write):
    """Neighbours of point i (within sqrt(eps2), itself included) from the 27 grid cells
    around its own: their number, and when ``write`` their indices into ``out``."""
    c0 = cell[i]
    cz0 = c0 % dims[2]
    cy0 = (c0 // dims[2]) % dims[1]
    cx0 = c0 // (dims[1] * dims[2])
    n = sorted_cells.shape[0]
    k = 0
    for x in range(max(cx0 - 1, 0), min(cx0 + 2, dims[0])):
        for y in range(max(cy0 - 1, 0), min(cy0 + 2, dims[1])):
            for z in range(max(cz0 - 1, 0), min(cz0 + 2, dims[2])):
                key = (x * dims[1] + y) * dims[2] + z
                a = np.searchsorted(sorted_cells, key)
                while a < n and sorted_cells[a] == key:
                    j = order[a]
                    d2 = 0.0
                    for e in range(3):
                        t = points[i, e] - points[j, e]
                        d2 += t * t
                    if d2 <= eps2:
                        if write:
                            out[k] = j
                        k += 1
                    a += 1
    return k


@njit(cache=True)
def _dbscan_grid(points, eps, min_points):
    """DBSCAN labels (-1: noise) of points (N, 3) and the number of clusters: neighbours
    within eps (a point's neighbourhood includes itself), clusters numbered in order of
    their lowest core point and grown fully before the next starts, so a border point two
    clusters reach belongs to the lower-numbered one. Neighbours are looked up in a grid
    of eps cells."""
    n = points.shape[0]
    label = np.full(n, -1, np.int64)
    if n == 0:
        return label, 0
    eps2 = eps * eps
    lo = np.empty(3)
    dims = np.empty(3, np.int64)
    for a in range(3):
        lo[a] = points[:, a].min()
        dims[a] = int(math.floor((points[:, a].max() - lo[a]) / eps)) + 1
    cell = np.empty(n, np.int64)
    for i in range(n):
        cx = int(math.floor((points[i, 0] - lo[0]) / eps))
        cy = int(math.floor((points[i, 1] - lo[1]) / eps))
        cz = int(math.floor((points[i, 2] - lo[2]) / eps))
        cell[i] = (cx * dims[1] + cy) * dims[2] + cz
    order = np.argsort(cell, kind="mergesort")
    sorted_cells = cell[order]
    start = np.zeros(n + 1, np.int64)
    for i in range(n):
        start[i + 1] = start[i] + _neighbours(i, points, cell, dims, sorted_cells, order,
                                              eps2, start, False)
    nbrs = np.empty(start[n], np.int64)
    for i in range(n):
        _neighbours(i, points, cell, dims, sorted_cells, order, eps2, nbrs[start[i]:], True)
    stack = np.empty(n + 1, np.int64)
    n_clusters = 0
    for i in range(n):
        if start[i + 1] - start[i] < min_points or label[i] != -1:
            continue
        label[i] = n_clusters
        stack[0] = i
        top = 1
        while top > 0:
            top -= 1
            j = stack[top]
            if start[j + 1] - start[j] < min_points:
                continue
            for q in range(start[j], start[j + 1]):
                k = nbrs[q]
                if label[k] == -1:
                    label[k] = n_clusters
                    stack[top] = k
                    top += 1
        n_clusters += 1
    return label, n_clusters


def dbscan_labels(points: np.ndarray, eps: float, min_points: int) -> tuple[np.ndarray, int]:
    """Cluster label per point of ``points`` (N, 3) (-1: noise) and the number of clusters
    (see :func:`_dbscan_grid` for the order)."""
    pts = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
    if not (math.isfinite(eps) and eps > 0):
        raise ValueError(f"eps must be a positive distance (m), got {eps!r}")
    if not np.all(np.isfinite(pts)):
        raise ValueError("points must be finite")
    return _dbscan_grid(pts, float(eps), int(min_points))


def dbscan(points: np.ndarray, eps: float, min_points: int) -> list[np.ndarray]:
    """Clusters of ``points`` (N, 3) as sorted index arrays; noise is left out. A point's
    neighbourhood includes itself."""
    label, k = dbscan_labels(points, eps, min_points)
    if k == 0:
        return []
    order = np.argsort(label, kind="stable")
    bounds = np.searchsorted(label[order], np.arange(k + 1))
    return [order[bounds[c]:bounds[c + 1]] for c in range(k)]


# --- tracking --------------------------------------------------------------------------------

@dataclass(eq=False)
class _Box:
    """One frame of a track: the box (centre, full size), the filter's velocity and
    acceleration, the cluster it came from and the classification flags."""

    t_us: int
    centre: np.ndarray
    size: np.ndarray
    vel: np.ndarray = field(default_factory=lambda: np.zeros(2))
    acc: np.ndarray = field(default_factory=lambda: np.zeros(2))
    n_points: int = 0
    spread: np.ndarray = field(default_factory=lambda: np.zeros(3))
    estimated: bool = False
    candidate: bool = False
    dynamic: bool = False


@dataclass(eq=False)
class _Track:
    boxes: deque  # _Box, newest first
    clouds: deque  # the cluster points (N, 3), newest first
    x: np.ndarray  # filter state x, y, vx, vy, ax, ay
    P: np.ndarray

    def copy(self) -> _Track:
        return _Track(deque(self.boxes, maxlen=self.boxes.maxlen),
                      deque(self.clouds, maxlen=self.clouds.maxlen), self.x.copy(),
                      self.P.copy())


def _iou(c1, s1, c2, s2) -> float:
    """The original's 3-D IoU of two axis-aligned boxes (centre, size): per axis the
    overlap, or the smaller side where one box spans the other; 0 without overlap."""
    overlap = np.empty(3)
    for a in range(3):
        l1 = c1[a] + s1[a] / 2 - (c2[a] - s2[a] / 2)
        l2 = c2[a] + s2[a] / 2 - (c1[a] - s1[a] / 2)
        overlap[a] = min(l1, l2)
        if max(l1, l2) <= max(s1[a], s2[a]):
            overlap[a] = min(s1[a], s2[a])
    if np.any(overlap <= 0):
        return 0.0
    inter = float(np.prod(overlap))
    return inter / (float(np.prod(s1)) + float(np.prod(s2)) - inter)


_FEATURE_WEIGHTS = np.array([2, 2, 2, 1, 1, 1, 0.5, 0.5, 0.5, 0.5])


def _feature(b: _Box, cam: np.ndarray) -> np.ndarray:
    return np.concatenate([b.centre - cam, b.size, [b.n_points], b.spread]) * _FEATURE_WEIGHTS


def _cosine(a: np.ndarray, b: np.ndarray) -> float:
    d = float(np.linalg.norm(a) * np.linalg.norm(b))
    return float(a @ b) / d if d > 0 else math.nan


class DynamicObstacleTracker:
    """The detector and tracker of one flight (see the module docstring). ``camera``: the
    frames' camera; ``config``: the parameters (default: :meth:`DetectorConfig.for_camera`).
    """

    def __init__(self, camera: CameraConfig, config: DetectorConfig | None = None):
        self.camera = camera
        self.config = cfg = DetectorConfig.for_camera(camera) if config is None else config
        n_side = int(round(2.0 * cfg.local_range_m / cfg.voxel_m))
        self._counts = np.zeros(n_side ** 3, np.int32)
        n_pix = camera.width * camera.height
        self._touched = np.empty(n_pix, np.int64)
        self._pts = np.empty((n_pix, 3))
        q, r = cfg.kf_q, cfg.kf_r
        self._Q = np.diag([q[0], q[0], q[1], q[1], q[2], q[2]])
        self._R = np.diag([r[0], r[0], r[1], r[1], r[2], r[2]])
        self.tracks: list[_Track] = []
        self.poses: deque = deque(maxlen=cfg.frame_skip + 1)  # (p, r_world_optical) newest 1st
        self._dynamic = ObstacleStates.empty()
        self.frames = 0
        self.last_t_us: int | None = None
        #: the last frame's clustered boxes: centres (K, 3) and sizes (K, 3)
        self.detections = (np.zeros((0, 3)), np.zeros((0, 3)))

    # -- per frame ---------------------------------------------------------------------------
    def update(self, frame: DepthFrame, t_us: int | None = None) -> None:
        """Detect, track and classify with one depth frame, taken at ``t_us`` (default:
        the frame's own time stamp; times must increase from frame to frame)."""
        cam = np.asarray(frame.p_world_camera, dtype=np.float64).reshape(3)
        r = np.ascontiguousarray(frame.r_world_optical, dtype=np.float64)
        t_us = int(frame.t_us if t_us is None else t_us)
        if self.last_t_us is not None and t_us <= self.last_t_us:
            raise ValueError(f"depth frames must come in time order (t_us {t_us} after "
                             f"{self.last_t_us})")
        self.last_t_us = t_us
        self.poses.appendleft((cam, r))
        dets, clouds = self._detect(frame, cam, r, t_us)
        self.detections = (np.array([b.centre for b in dets]).reshape(-1, 3),
                           np.array([b.size for b in dets]).reshape(-1, 3))
        self._track(dets, clouds, cam, t_us)
        self._classify()
        self.frames += 1

    def _detect(self, frame: DepthFrame, cam, r, t_us: int):
        cfg, c = self.config, self.camera
        depth = np.asarray(frame.depth)
        if depth.shape != (c.height, c.width):
            raise ValueError(f"frame.depth has shape {depth.shape}, the detector's camera is "
                             f"{c.height} x {c.width}")
        n = _filtered_points(depth, float(c.fx), float(c.fy), float(c.cx), float(c.cy), r,
                             cam, int(cfg.margin_px), cfg.depth_min_m, cfg.depth_max_m,
                             cfg.ground_height_m, cfg.local_range_m, cfg.voxel_m,
                             int(cfg.voxel_min_points), self._counts, self._touched, self._pts)
        pts = self._pts[:n].copy()
        boxes, clouds = [], []
        for idx in dbscan(pts, cfg.dbscan_eps_m, cfg.dbscan_min_points):
            p = pts[idx]
            lo, hi = p.min(axis=0), p.max(axis=0)
            size = hi - lo
            size[:2] = np.maximum(size[:2], 0.1)
            boxes.append(_Box(t_us, 0.5 * (lo + hi), size, n_points=len(p),
                              spread=p.std(axis=0)))
            clouds.append(p)
        return boxes, clouds

    def _new_filter(self, b: _Box) -> tuple[np.ndarray, np.ndarray]:
        x = np.zeros(6)
        x[:2] = b.centre[:2]
        return x, np.eye(6) * self.config.kf_p

    def _filter(self, tr: _Track, b: _Box, t_us: int) -> _Box:
        """One Kalman step of track ``tr`` with the box ``b`` seen at ``t_us``; the
        filtered box (its height and size are the box's)."""
        hist = tr.boxes
        k = min(self.config.kf_average_frames, len(hist))
        prev = hist[k - 1]
        span = (t_us - prev.t_us) * 1e-6
        dt = (t_us - hist[0].t_us) * 1e-6
        vel = (b.centre[:2] - prev.centre[:2]) / span
        acc = (vel - prev.vel) / span
        z = np.concatenate([b.centre[:2], vel, acc])
        A = np.eye(6)
        A[0, 2] = A[1, 3] = A[2, 4] = A[3, 5] = dt
        A[0, 4] = A[1, 5] = 0.5 * dt * dt
        x = A @ tr.x
        P = A @ tr.P @ A.T + self._Q
        K = P @ np.linalg.inv(P + self._R)  # H = I
        tr.x = x + K @ (z - x)
        tr.P = (np.eye(6) - K) @ P
        return _Box(t_us, np.array([tr.x[0], tr.x[1], b.centre[2]]), b.size.copy(),
                    vel=tr.x[2:4].copy(), acc=tr.x[4:6].copy(), n_points=b.n_points,
                    spread=b.spread)

    @staticmethod
    def _best(feat, det: _Box, feats, proped, candidates, threshold) -> int:
        """The candidate track (index) most similar to the detection (ties: the later
        one), if similar and overlapping enough; else -1."""
        best, best_j = -1.0, -1
        for j in candidates:
            s = _cosine(feats[j], feat)
            if s >= best:
                best, best_j = s, j
        if best_j >= 0 and best > threshold and \
                _iou(det.centre, det.size, proped[best_j].centre, proped[best_j].size) > 0:
            return best_j
        return -1

    def _track(self, dets, clouds, cam, t_us: int) -> None:
        cfg = self.config
        proped = []
        for tr in self.tracks:
            b = tr.boxes[0]
            c = b.centre.copy()
            c[:2] += b.vel * ((t_us - b.t_us) * 1e-6)
            proped.append(_Box(b.t_us, c, b.size, n_points=b.n_points, spread=b.spread,
                               estimated=b.estimated))
        feats = [_feature(p, cam) for p in proped]
        det_feats = [_feature(d, cam) for d in dets]
        everyone = range(len(proped))
        match = [self._best(f, d, feats, proped, everyone, cfg.similarity_threshold)
                 for f, d in zip(det_feats, dets)]
        lost = [j for j in everyone if j not in match and self.tracks[j].boxes[0].dynamic]
        for i, d in enumerate(dets):  # a lost, predicted dynamic track may be taken again
            if match[i] >= 0:
                continue
            retake = [j for j in lost if proped[j].estimated]
            if retake:
                j = self._best(det_feats[i], d, feats, proped, retake,
                               cfg.retrack_similarity_threshold)
                if j >= 0:
                    match[i] = j
                    lost.remove(j)
        new_tracks = []
        for d, cloud, j in zip(dets, clouds, match):
            if j >= 0:
                tr = self.tracks[j].copy()
                b = self._filter(tr, d, t_us)
            else:
                x, P = self._new_filter(d)
                tr = _Track(deque(maxlen=cfg.history_size), deque(maxlen=cfg.frame_skip + 1),
                            x, P)
                b = d
            tr.boxes.appendleft(b)
            tr.clouds.appendleft(cloud)
            new_tracks.append(tr)
        horizon = min(cfg.prediction_size, cfg.history_size - 1)
        for j in lost:
            tr = self.tracks[j]
            if self._estimated_frames(tr) >= horizon:
                continue
            tr = tr.copy()
            last = tr.boxes[0]
            moved = _Box(t_us, proped[j].centre, last.size.copy(), n_points=last.n_points,
                         spread=last.spread)
            b = self._filter(tr, moved, t_us)
            b.dynamic = b.estimated = b.candidate = True
            tr.boxes.appendleft(b)
            tr.clouds.appendleft(tr.clouds[0])
            new_tracks.append(tr)
        for tr in new_tracks:  # keep a steady size
            b = tr.boxes[0]
            if b.estimated or len(tr.boxes) < cfg.fix_size_history:
                continue
            prev = tr.boxes[1].size
            if np.all(np.abs(b.size - prev) / prev <= cfg.fix_size_ratio):
                b.size = prev.copy()
        self.tracks = new_tracks

    @staticmethod
    def _estimated_frames(tr: _Track) -> int:
        n = 0
        for b in tr.boxes:
            if not b.estimated:
                break
            n += 1
        return n

    def _in_fov(self, points: np.ndarray, pose) -> np.ndarray:
        p, r = pose
        c = (points - p) @ r  # optical frame: x right, y down, z forward
        z = c[:, 2]
        th, tv = (math.tan(a) for a in self.config.half_fov_rad)
        with np.errstate(divide="ignore", invalid="ignore"):
            return (z > 0) & (np.abs(c[:, 0]) < th * z) & (np.abs(c[:, 1]) < tv * z) & \
                (z < self.config.depth_max_m)

    def _votes(self, tr: _Track, gap: int) -> tuple[float, float]:
        """(vote ratio, skip ratio) of the track's current points against ``gap`` frames
        ago."""
        cfg = self.config
        b0, bg = tr.boxes[0], tr.boxes[gap]
        span = (b0.t_us - bg.t_us) * 1e-6
        cur, prev = tr.clouds[0], tr.clouds[gap]
        if span <= 0 or len(cur) == 0 or len(prev) == 0 or gap >= len(self.poses):
            return 0.0, math.inf
        v_box = (b0.centre - bg.centre) / span
        seen = self._in_fov(cur, self.poses[gap])
        n_points = int(np.count_nonzero(seen))
        skipped = len(cur) - n_points
        dist, idx = cKDTree(prev).query(cur[seen], distance_upper_bound=cfg.nearest_max_m)
        found = np.isfinite(dist)
        v = np.zeros((len(idx), 3))
        v[found] = (cur[seen][found] - prev[idx[found]]) / span
        v[:, 2] = 0.0
        nv, nb = np.linalg.norm(v, axis=1), float(np.linalg.norm(v_box))
        with np.errstate(divide="ignore", invalid="ignore"):
            sim = (v @ v_box) / (nv * nb)
        against = sim < 0  # (NaN: no displacement, not against)
        skipped += int(np.count_nonzero(against))
        n_points -= int(np.count_nonzero(against))
        votes = int(np.count_nonzero(~against & (nv > cfg.dynamic_speed_m_s)))
        vote_ratio = votes / n_points if n_points > 0 else 0.0
        skip_ratio = skipped / n_points if n_points > 0 else math.inf
        return vote_ratio, skip_ratio

    def _classify(self) -> None:
        cfg = self.config
        out: list[_Box] = []
        for tr in self.tracks:
            b0 = tr.boxes[0]
            if b0.estimated:
                e = self._estimate_box(tr)
                if self._size_ok(b0.size):
                    out.append(e)
                continue
            gap = min(len(tr.clouds) - 1, cfg.frame_skip)
            if len(tr.boxes) > cfg.force_dynamic_range:
                n_dyn = sum(tr.boxes[j].dynamic for j in range(1, cfg.force_dynamic_range + 1))
                if n_dyn >= cfg.force_dynamic_frames:
                    b0.dynamic = True
                    out.append(b0)
                    continue
            if gap < 1:
                continue
            vote_ratio, skip_ratio = self._votes(tr, gap)
            if vote_ratio >= cfg.dynamic_vote_ratio and \
                    float(np.linalg.norm(b0.vel)) >= cfg.dynamic_speed_m_s and \
                    skip_ratio < cfg.max_skip_ratio:
                b0.candidate = True
                k = cfg.dynamic_consistency
                if len(tr.boxes) >= k and all(tr.boxes[j].candidate for j in range(k)):
                    b0.dynamic = True
                    out.append(b0)
        if cfg.constrain_size:
            out = [b for b in out if b.estimated or self._size_ok(b.size)]
        if out:
            self._dynamic = ObstacleStates(
                np.array([b.centre for b in out]),
                np.array([[b.vel[0], b.vel[1], 0.0] for b in out]),
                np.array([b.size for b in out]))
        else:
            self._dynamic = ObstacleStates.empty()

    @staticmethod
    def _estimate_box(tr: _Track) -> _Box:
        b0 = tr.boxes[0]
        last = next((b for b in tr.boxes if not b.estimated), b0)
        dx, dy = b0.centre[0] - last.centre[0], b0.centre[1] - last.centre[1]
        size = b0.size.copy()
        size[0] = min(abs(dx) + size[0], 1.5 * size[0])
        size[1] = min(abs(dy) + size[1], 1.5 * size[1])
        return _Box(b0.t_us, np.array([b0.centre[0] - dx / 2, b0.centre[1] - dy / 2,
                                       b0.centre[2]]), size, vel=b0.vel.copy(),
                    estimated=True, dynamic=True)

    def _size_ok(self, size: np.ndarray) -> bool:
        if not self.config.constrain_size:
            return True
        tol = np.asarray(self.config.size_tolerance_m)
        return any(bool(np.all(np.abs(size - np.asarray(t)) < tol))
                   for t in self.config.target_sizes)

    # -- output ------------------------------------------------------------------------------
    def obstacles(self) -> ObstacleStates:
        """The dynamic obstacles after the last frame (all of them; :func:`in_range`
        selects as the original's service does)."""
        return self._dynamic


def in_range(obstacles: ObstacleStates, position, range_m: float) -> ObstacleStates:
    """The obstacles whose centre is within ``range_m`` of ``position`` horizontally,
    nearest first (ties: in the given order), as the original's ``get_dynamic_obstacles``
    service (and its ground-truth twin, the simulation's ``fakeDetector``) answer."""
    p = np.asarray(position, dtype=np.float64).reshape(3)
    if obstacles.count == 0:
        return obstacles
    d = np.hypot(obstacles.position[:, 0] - p[0], obstacles.position[:, 1] - p[1])
    keep = np.flatnonzero(d <= range_m)
    return obstacles.take(keep[np.argsort(d[keep], kind="stable")])
