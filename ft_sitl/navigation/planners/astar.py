"""26-connected A* on a voxel lattice: EGO-Planner's path search around colliding stretches.

The search runs on the lattice of the occupancy map's voxels: voxel ``i`` (integer triple)
has its centre at ``origin + (i + 0.5) * resolution``. The map is seen through a small
protocol, :class:`OccupancyView`: a vectorised ``occupied(points (N, 3)) -> bool (N,)``
callable (the inflated map, unknown = free), the resolution, and optional world bounds
outside which everything counts as occupied. A ``LocalMap`` fits with
``OccupancyView(m.occupied_inflated, m.config.resolution)``.

How it works (behaviours from EGO's ``dyn_a_star``, our own code):

- Occupied start/goal points are moved along the start-goal line, one voxel at a time, to
  the first free voxel (EGO does the same; a line occupied end to end gives
  ``AStarStatus.BLOCKED``).
- The occupancy of a box of voxels around start and goal (``margins_m`` beyond their
  bounding box, clipped to the bounds) is read at once (one vectorised ``occupied`` call,
  or the view's optional ``block`` slice) and searched by a numba kernel: 26 neighbours
  with step costs ``resolution * (1, sqrt 2, sqrt 3)``, the consistent octile ("diagonal")
  heuristic multiplied by ``1 + tie_breaker`` (EGO: 1 + 1e-4, which prefers nodes nearer
  the goal among equal ``f``), ties on ``f`` broken by smaller ``h``, an indexed binary
  heap with decrease-key. If the box is exhausted without reaching the goal and the
  search touched a face of the box that is not a face of the bounds, the next, larger
  margin is tried; EGO searches a fixed pool of 100^3 voxels (+-5 m) around the start-goal
  midpoint instead.
- The effort is capped by expansions (``max_expansions``, counted over all boxes; the
  default is deterministic) and optionally by wall-clock time (``time_limit_s``; EGO's cap
  is 0.2 s), checked every ``chunk`` expansions.

The result is the path of voxel centres from the start voxel to the goal voxel (both
included), or None.
"""

from __future__ import annotations

import enum
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numba import njit

__all__ = ["AStarMemo", "AStarResult", "AStarStatus", "OccupancyView", "astar_path",
           "search"]

# kernel return codes
_FOUND, _EXHAUSTED, _BUDGET = 0, 1, 2


@dataclass(frozen=True, eq=False)
class OccupancyView:
    """What the planners need from an occupancy map.

    ``occupied(points (N, 3)) -> bool (N,)`` must be vectorised and already inflated;
    ``resolution`` is the voxel edge (m); ``bounds`` an optional ``(lo (3,), hi (3,))`` world
    box outside which points count as occupied; ``origin`` the lattice origin (voxel centres
    at ``origin + (i + 0.5) * resolution``; it should be the map's own so that A* voxels are
    map voxels).

    ``block`` is an optional fast path for A*: ``block(lo (3,) int, shape (3,) int) -> bool
    array of that shape``, the occupancy of the voxels ``lo .. lo + shape - 1`` of this
    lattice (bounds not applied), which must agree with ``occupied`` at the voxel centres.
    A map that stores a voxel array can answer it with one slice, instead of the ~0.1 us per
    point of ``occupied`` on generated centres (tens of ms for a 100 x 100 x 40 box).

    ``lattice`` is another optional fast path: ``lattice(xs, ys, zs) -> bool array (len(xs),
    len(ys), len(zs))``, ``occupied`` at every point of the product of three coordinate
    vectors; A* then asks it for the box's voxel centres, computed as for ``occupied``, so
    the answer is the same point by point (``LocalMap.occupied_inflated_lattice``).

    ``revision`` is optional: ``revision() -> int``, a value that changes whenever
    ``occupied`` may have changed; an :class:`AStarMemo` then reuses an answer found at the
    same revision without reading the map again.
    """

    occupied: Callable[[np.ndarray], np.ndarray]
    resolution: float
    bounds: tuple[np.ndarray, np.ndarray] | None = None
    origin: np.ndarray = field(default_factory=lambda: np.zeros(3))
    block: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None
    lattice: Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray] | None = None
    revision: Callable[[], int] | None = None

    def __post_init__(self):
        if not callable(self.occupied):
            raise TypeError("occupied must be a callable points (N, 3) -> bool (N,)")
        if not (math.isfinite(self.resolution) and self.resolution > 0):
            raise ValueError(f"resolution must be a positive number of metres, "
                             f"got {self.resolution!r}")
        object.__setattr__(self, "resolution", float(self.resolution))
        object.__setattr__(self, "origin", np.asarray(self.origin, dtype=float).reshape(3))
        if self.bounds is not None:
            lo, hi = (np.asarray(b, dtype=float).reshape(3) for b in self.bounds)
            if np.any(hi <= lo):
                raise ValueError(f"bounds: hi must exceed lo, got {lo}, {hi}")
            object.__setattr__(self, "bounds", (lo, hi))

    @classmethod
    def from_map(cls, local_map, bounds=None) -> OccupancyView:
        """View of the ``LocalMap`` of ``ft_sitl.navigation.maps.mapping`` (duck-typed: its
        ``occupied_inflated(points)`` and ``resolution_m``; its voxels are world-aligned,
        centres at ``(i + 0.5) * resolution``, which is this view's default lattice; its
        ``occupied_inflated_lattice`` and ``revision`` when it has them)."""
        lattice = getattr(local_map, "occupied_inflated_lattice", None)
        revision = (lambda: local_map.revision) if hasattr(local_map, "revision") else None
        return cls(local_map.occupied_inflated, local_map.resolution_m, bounds=bounds,
                   lattice=lattice, revision=revision)

    def is_occupied(self, points) -> np.ndarray:
        """``occupied(points)`` with the bounds applied: bool ``(N,)``."""
        pts = np.asarray(points, dtype=float).reshape(-1, 3)
        occ = np.asarray(self.occupied(pts), dtype=bool).reshape(pts.shape[0])
        if self.bounds is not None:
            lo, hi = self.bounds
            occ = occ.copy()  # the callable's array may be its own
            _or_outside(pts, lo, hi, occ)
        return occ

    def box_occupancy(self, lo, shape) -> np.ndarray:
        """Occupancy of the voxels ``lo .. lo + shape - 1`` (bounds applied), bool array of
        ``shape``; through ``block`` when given, else ``occupied`` at the centres."""
        lo = np.asarray(lo, dtype=np.int64).reshape(3)
        shape = tuple(int(v) for v in shape)
        if self.block is not None:
            occ = np.asarray(self.block(lo, np.array(shape)), dtype=bool)
            if occ.shape != shape:
                raise ValueError(f"block returned shape {occ.shape}, expected {shape}")
        elif self.lattice is not None:
            axes = [self.origin[d] + (lo[d] + 0.5 + np.arange(shape[d])) * self.resolution
                    for d in range(3)]
            occ = np.asarray(self.lattice(*axes), dtype=bool)
            if occ.shape != shape:
                raise ValueError(f"lattice returned shape {occ.shape}, expected {shape}")
        else:
            pts = np.empty(shape + (3,))
            for d in range(3):
                c = self.origin[d] + (lo[d] + 0.5 + np.arange(shape[d])) * self.resolution
                pts[..., d] = c.reshape([-1 if e == d else 1 for e in range(3)])
            occ = np.asarray(self.occupied(pts.reshape(-1, 3)), dtype=bool).reshape(shape)
        if self.bounds is not None:
            out = np.zeros(shape, dtype=bool)
            for d in range(3):
                c = self.origin[d] + (lo[d] + 0.5 + np.arange(shape[d])) * self.resolution
                bad = (c < self.bounds[0][d]) | (c > self.bounds[1][d])
                out |= bad.reshape([-1 if e == d else 1 for e in range(3)])
            occ = occ | out
        return occ

    def voxel_of(self, points) -> np.ndarray:
        """Integer voxel indices of points, ``(N, 3)`` int64."""
        pts = np.asarray(points, dtype=float).reshape(-1, 3)
        return np.floor((pts - self.origin) / self.resolution).astype(np.int64)

    def centre_of(self, voxels) -> np.ndarray:
        """World centres of integer voxel indices, ``(N, 3)``."""
        return self.origin + (np.asarray(voxels, dtype=float) + 0.5) * self.resolution


class AStarStatus(enum.Enum):
    FOUND = "found"
    NO_PATH = "no_path"  # every reachable voxel of the largest box was expanded
    CAP = "cap"  # expansion or time cap reached first
    BLOCKED = "blocked"  # the whole start-goal line is occupied (no free endpoint)


@dataclass(frozen=True, eq=False)
class AStarResult:
    status: AStarStatus
    path: np.ndarray | None  # (M, 3) voxel centres, start voxel first; None unless FOUND
    expansions: int
    time_s: float

    @property
    def found(self) -> bool:
        return self.status is AStarStatus.FOUND


_OFFSETS = np.array([(dx, dy, dz) for dx in (-1, 0, 1) for dy in (-1, 0, 1) for dz in (-1, 0, 1)
                     if (dx, dy, dz) != (0, 0, 0)], dtype=np.int64)
_STEP = np.sqrt(np.sum(_OFFSETS ** 2, axis=1)).astype(np.float64)


@njit(cache=True)
def _or_outside(pts, lo, hi, occ):
    """``occ[i] |= pts[i]`` outside the box ``lo .. hi`` (a coordinate below ``lo`` or above
    ``hi``; NaN is inside, as numpy's comparisons have it): the bounds of
    :meth:`OccupancyView.is_occupied` without numpy's two reductions per call (10 us of
    its 12 us on a 30-point spline)."""
    for i in range(pts.shape[0]):
        for a in range(3):
            if pts[i, a] < lo[a] or pts[i, a] > hi[a]:
                occ[i] = True
                break


@njit(cache=True, inline="always")
def _less(fa, ha, fb, hb):
    return fa < fb or (fa == fb and ha < hb)


@njit(cache=True)
def _sift_up(pos_i, heap_node, heap_f, heap_h, heap_pos):
    node = heap_node[pos_i]
    f = heap_f[pos_i]
    h = heap_h[pos_i]
    while pos_i > 0:
        parent = (pos_i - 1) >> 1
        if _less(f, h, heap_f[parent], heap_h[parent]):
            heap_node[pos_i] = heap_node[parent]
            heap_f[pos_i] = heap_f[parent]
            heap_h[pos_i] = heap_h[parent]
            heap_pos[heap_node[pos_i]] = pos_i
            pos_i = parent
        else:
            break
    heap_node[pos_i] = node
    heap_f[pos_i] = f
    heap_h[pos_i] = h
    heap_pos[node] = pos_i


@njit(cache=True)
def _sift_down(pos_i, size, heap_node, heap_f, heap_h, heap_pos):
    node = heap_node[pos_i]
    f = heap_f[pos_i]
    h = heap_h[pos_i]
    while True:
        child = 2 * pos_i + 1
        if child >= size:
            break
        right = child + 1
        if right < size and _less(heap_f[right], heap_h[right], heap_f[child], heap_h[child]):
            child = right
        if _less(heap_f[child], heap_h[child], f, h):
            heap_node[pos_i] = heap_node[child]
            heap_f[pos_i] = heap_f[child]
            heap_h[pos_i] = heap_h[child]
            heap_pos[heap_node[pos_i]] = pos_i
            pos_i = child
        else:
            break
    heap_node[pos_i] = node
    heap_f[pos_i] = f
    heap_h[pos_i] = h
    heap_pos[node] = pos_i


@njit(cache=True, inline="always")
def _octile(i, j, k, gi, gj, gk):
    a = abs(i - gi)
    b = abs(j - gj)
    c = abs(k - gk)
    # sort a <= b <= c
    if a > b:
        a, b = b, a
    if b > c:
        b, c = c, b
    if a > b:
        a, b = b, a
    return math.sqrt(3.0) * a + math.sqrt(2.0) * (b - a) + (c - b)


@njit(cache=True)
def _astar_kernel(blocked, ny, nz, start, goal, g, parent, state, heap_node, heap_f, heap_h,
                  heap_pos, counters, budget, offsets, lin_off, step, tie):
    """Resumable A* over the flat ``blocked`` grid (x-major, ``(nx, ny, nz)``, with a border
    of blocked voxels so that neighbours need no bounds checks). ``state``: 0 unseen,
    1 open, 2 closed. ``counters``: [heap size, expansions, started]. Costs in voxels."""
    nyz = ny * nz
    gi = goal // nyz
    gj = (goal // nz) % ny
    gk = goal % nz
    if counters[2] == 0:
        counters[2] = 1
        h0 = _octile(start // nyz, (start // nz) % ny, start % nz, gi, gj, gk) * tie
        g[start] = 0.0
        parent[start] = -1
        state[start] = 1
        heap_node[0] = start
        heap_f[0] = h0
        heap_h[0] = h0
        heap_pos[start] = 0
        counters[0] = 1
    done = 0
    while done < budget:
        size = counters[0]
        if size == 0:
            return 1
        node = heap_node[0]
        size -= 1
        counters[0] = size
        if size > 0:
            heap_node[0] = heap_node[size]
            heap_f[0] = heap_f[size]
            heap_h[0] = heap_h[size]
            heap_pos[heap_node[0]] = 0
            _sift_down(0, size, heap_node, heap_f, heap_h, heap_pos)
        state[node] = 2
        if node == goal:
            return 0
        done += 1
        counters[1] += 1
        i = node // nyz
        j = (node // nz) % ny
        k = node % nz
        g_node = g[node]
        for n in range(lin_off.shape[0]):
            nb = node + lin_off[n]
            if blocked[nb] != 0 or state[nb] == 2:
                continue
            g_new = g_node + step[n]
            if state[nb] == 1:
                if g_new >= g[nb]:
                    continue
                g[nb] = g_new
                parent[nb] = node
                p = heap_pos[nb]
                heap_f[p] = g_new + heap_h[p]
                _sift_up(p, heap_node, heap_f, heap_h, heap_pos)
            else:
                h = _octile(i + offsets[n, 0], j + offsets[n, 1], k + offsets[n, 2],
                            gi, gj, gk) * tie
                g[nb] = g_new
                parent[nb] = node
                state[nb] = 1
                size = counters[0]
                heap_node[size] = nb
                heap_f[size] = g_new + h
                heap_h[size] = h
                heap_pos[nb] = size
                counters[0] = size + 1
                _sift_up(size, heap_node, heap_f, heap_h, heap_pos)
    return 2


def _free_endpoint(grid: OccupancyView, a: np.ndarray, b: np.ndarray) -> np.ndarray | None:
    """Voxel of ``a`` if free, else of the first free point on the line a -> b sampled every
    voxel (EGO's endpoint adjustment); None if the line is occupied end to end."""
    length = float(np.linalg.norm(b - a))
    n = max(int(math.ceil(length / grid.resolution)), 0)
    pts = a + np.linspace(0.0, 1.0, n + 1)[:, None] * (b - a) if n else a[None, :]
    vox = grid.voxel_of(pts)
    occ = grid.is_occupied(grid.centre_of(vox))
    free = np.flatnonzero(~occ)
    return vox[free[0]] if free.size else None


def _touches_open_face(state: np.ndarray, lo, hi, b_lo, b_hi) -> bool:
    """True if a closed voxel lies on a face of the box that is not a face of the bounds
    (so the search might have gone on outside the box)."""
    for axis in range(3):
        for side, at_bound in ((0, b_lo is not None and lo[axis] <= b_lo[axis]),
                               (-1, b_hi is not None and hi[axis] >= b_hi[axis])):
            if at_bound:
                continue
            face = np.take(state, side, axis=axis)
            if np.any(face == 2):
                return True
    return False


class AStarMemo:
    """Answers of :func:`search` for one view, to answer a repeated search (same start and
    goal voxel, same settings, no time limit) without searching again.

    A search without a time limit is a deterministic function of its endpoint voxels, its
    settings and the occupancy of the boxes it read, so a stored answer is returned when
    the view's ``revision`` is the one it was found at, or else when every box it read
    still has the same occupancy (read again and compared voxel for voxel: ~1 ms against
    the tens of ms of a search that exhausts its expansions). Only answers that took at
    least ``check_above`` expansions are checked that way: a cheaper search costs about
    what the check does, and the check is wasted when the map has changed. At most
    ``max_entries`` answers (the oldest are dropped)."""

    def __init__(self, max_entries: int = 64, check_above: int = 10_000):
        self.max_entries = int(max_entries)
        self.check_above = int(check_above)
        self._grid: OccupancyView | None = None
        self._answers: dict = {}  # key -> [revision, boxes read, result]
        self.hits = 0
        self.misses = 0
        self.checks = 0  # answers checked against the boxes they read
        self.stale = 0  # ... that the map had changed

    def get(self, grid: OccupancyView, key) -> AStarResult | None:
        if grid is not self._grid:
            self._grid = grid
            self._answers.clear()
        entry = self._answers.get(key)
        if entry is not None:
            rev = grid.revision() if grid.revision is not None else None
            if rev is None or entry[0] != rev:
                if entry[2].expansions < self.check_above:
                    entry = None
                else:
                    self.checks += 1
                    if not all(np.array_equal(grid.box_occupancy(lo, shape), occ)
                               for lo, shape, occ in entry[1]):
                        self.stale += 1
                        entry = None
                    else:
                        entry[0] = rev
        if entry is None:
            self.misses += 1
            return None
        self.hits += 1
        return entry[2]

    def put(self, grid: OccupancyView, key, boxes: list, result: AStarResult) -> None:
        if grid is not self._grid:
            self._grid = grid
            self._answers.clear()
        self._answers.pop(key, None)
        while len(self._answers) >= self.max_entries:
            self._answers.pop(next(iter(self._answers)))
        self._answers[key] = [grid.revision() if grid.revision is not None else None, boxes,
                              result]


def search(start, goal, grid: OccupancyView, *, max_expansions: int = 100_000,
           time_limit_s: float | None = None, margins_m: tuple[float, ...] = (1.0, 2.5, 5.0),
           tie_breaker: float = 1e-4, chunk: int = 4096,
           memo: AStarMemo | None = None) -> AStarResult:
    """A* from ``start`` to ``goal`` (world points) on ``grid``'s voxel lattice. With a
    ``memo``, a search without a time limit that was already done between the same voxels
    on the same occupancy returns the stored answer (:class:`AStarMemo`)."""
    t0 = time.perf_counter()
    if max_expansions < 1:
        raise ValueError(f"max_expansions must be >= 1, got {max_expansions}")
    if not margins_m or any(m < 0 for m in margins_m):
        raise ValueError(f"margins_m must be non-negative and non-empty, got {margins_m!r}")
    a = np.asarray(start, dtype=float).reshape(3)
    b = np.asarray(goal, dtype=float).reshape(3)
    sv = _free_endpoint(grid, a, b)
    gv = _free_endpoint(grid, b, a)
    if sv is None or gv is None:
        return AStarResult(AStarStatus.BLOCKED, None, 0, time.perf_counter() - t0)
    if np.array_equal(sv, gv):
        return AStarResult(AStarStatus.FOUND, grid.centre_of(sv[None, :]), 0,
                           time.perf_counter() - t0)
    if memo is None or time_limit_s is not None:
        return _search_boxes(sv, gv, grid, t0, max_expansions, time_limit_s, margins_m,
                             tie_breaker, chunk)
    key = (tuple(int(v) for v in sv), tuple(int(v) for v in gv), int(max_expansions),
           tuple(float(m) for m in margins_m), float(tie_breaker))
    found = memo.get(grid, key)
    if found is None:
        boxes: list = []
        found = _search_boxes(sv, gv, grid, t0, max_expansions, None, margins_m,
                              tie_breaker, chunk, boxes)
        memo.put(grid, key, boxes, found)
    return AStarResult(found.status, None if found.path is None else found.path.copy(),
                       found.expansions, time.perf_counter() - t0)


def _search_boxes(sv, gv, grid: OccupancyView, t0: float, max_expansions: int,
                  time_limit_s: float | None, margins_m, tie_breaker: float,
                  chunk: int, boxes: list | None = None) -> AStarResult:
    """:func:`search` from the free start voxel ``sv`` to the free goal voxel ``gv``
    (distinct) through the boxes of ``margins_m``; the boxes read and their occupancy are
    appended to ``boxes`` as ``(lo, shape, occupancy)``."""
    res = grid.resolution
    b_lo = b_hi = None
    if grid.bounds is not None:
        b_lo = np.ceil((grid.bounds[0] - grid.origin) / res - 0.5).astype(np.int64)
        b_hi = np.floor((grid.bounds[1] - grid.origin) / res - 0.5).astype(np.int64)
    expansions = 0
    last_shape = None
    status = AStarStatus.NO_PATH
    for margin in margins_m:
        m = int(math.ceil(margin / res))
        lo = np.minimum(sv, gv) - m
        hi = np.maximum(sv, gv) + m
        if grid.bounds is not None:
            lo = np.maximum(lo, np.minimum(b_lo, np.minimum(sv, gv)))
            hi = np.minimum(hi, np.maximum(b_hi, np.maximum(sv, gv)))
        shape = hi - lo + 1
        if last_shape is not None and np.array_equal(shape, last_shape[0]) and \
                np.array_equal(lo, last_shape[1]):
            break  # clipped by the bounds: a larger margin gives the same box
        last_shape = (shape, lo)
        occ = grid.box_occupancy(lo, shape)
        if boxes is not None:
            boxes.append((lo.copy(), shape.copy(), occ))
        # padded by one blocked voxel on every side
        nx, ny, nz = (int(v) + 2 for v in shape)
        blocked = np.ones((nx, ny, nz), dtype=np.uint8)
        blocked[1:-1, 1:-1, 1:-1] = occ
        blocked = blocked.reshape(-1)
        n_nodes = nx * ny * nz
        s_rel = sv - lo + 1
        g_rel = gv - lo + 1
        s_idx = int((s_rel[0] * ny + s_rel[1]) * nz + s_rel[2])
        g_idx = int((g_rel[0] * ny + g_rel[1]) * nz + g_rel[2])
        blocked[s_idx] = 0
        blocked[g_idx] = 0
        lin_off = (_OFFSETS[:, 0] * ny + _OFFSETS[:, 1]) * nz + _OFFSETS[:, 2]
        g = np.empty(n_nodes)
        parent = np.empty(n_nodes, dtype=np.int64)
        state = np.zeros(n_nodes, dtype=np.uint8)
        heap_node = np.empty(n_nodes, dtype=np.int64)
        heap_f = np.empty(n_nodes)
        heap_h = np.empty(n_nodes)
        heap_pos = np.empty(n_nodes, dtype=np.int64)
        counters = np.zeros(3, dtype=np.int64)
        while True:
            budget = max_expansions - expansions
            if time_limit_s is not None:
                budget = min(budget, chunk)
            code = _astar_kernel(blocked, ny, nz, s_idx, g_idx, g, parent, state, heap_node,
                                 heap_f, heap_h, heap_pos, counters, budget, _OFFSETS, lin_off,
                                 _STEP, 1.0 + tie_breaker)
            expansions += int(counters[1])
            counters[1] = 0
            if code == _FOUND:
                chain = [g_idx]
                while chain[-1] != s_idx:
                    chain.append(int(parent[chain[-1]]))
                idx = np.array(chain[::-1], dtype=np.int64)
                rel = np.stack([idx // (ny * nz), (idx // nz) % ny, idx % nz], axis=1) - 1
                return AStarResult(AStarStatus.FOUND, grid.centre_of(rel + lo), expansions,
                                   time.perf_counter() - t0)
            if code == _EXHAUSTED:
                status = AStarStatus.NO_PATH
                inner = state.reshape(nx, ny, nz)[1:-1, 1:-1, 1:-1]
                if not _touches_open_face(inner, lo, hi, b_lo, b_hi):
                    # the reachable set lies inside the box: a larger box cannot help
                    return AStarResult(status, None, expansions, time.perf_counter() - t0)
                break
            if expansions >= max_expansions or (
                    time_limit_s is not None and time.perf_counter() - t0 >= time_limit_s):
                return AStarResult(AStarStatus.CAP, None, expansions, time.perf_counter() - t0)
    return AStarResult(status, None, expansions, time.perf_counter() - t0)


def astar_path(start, goal, grid: OccupancyView, **kwargs) -> np.ndarray | None:
    """The voxel-centre path of :func:`search`, or None when there is none."""
    return search(start, goal, grid, **kwargs).path
