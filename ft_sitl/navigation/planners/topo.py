"""Fast-Planner's topological roadmap: the path search of PGO (path-guided optimisation).

Behaviours and defaults are those of Fast-Planner's ``TopologyPRM`` and the collision
range of its planner manager (Zhou et al., ICRA 2020; HKUST-Aerial-Robotics/Fast-Planner,
``topo_prm.cpp``; see /work/shared/docs/planner-facts.md); the code is our own.

Distances come from an :class:`EsdfGrid`, a snapshot of the local map's signed ESDF
(:meth:`~ft_sitl.navigation.maps.mapping.LocalMap.update_esdf`): free voxels hold the distance to
the nearest planning-occupied voxel centre (>= one voxel), occupied voxels ``<= 0``. Like
the original, the search reads it two ways: per voxel (Fast-Planner's "coarse" distance,
used for the sample clearance, the collision range and line of sight) and trilinearly with
its gradient (the shortcut's push, the optimiser). Points outside the snapshot are clamped
onto it per axis (as ``LocalMap.esdf``); points outside the flight volume (``bounds``) have
distance -1, i.e. they are blocked.

The search (:func:`find_topo_paths`), from ``start`` to ``end`` (the free points just before
and after the colliding stretch of the local segment, :func:`collision_range`):

1. **Samples.** Up to ``max_samples`` (2000) uniform draws in a box centred between start
   and end, x along ``end - start`` (half extents ``(L/2 + 1, 3.5, 1.0)`` m, y horizontal,
   z completing the frame); draws with distance ``<= clearance`` (0.3 m) are dropped. The
   draws come from the caller's ``numpy.random.Generator``, so a search is reproducible.
2. **Visibility roadmap** (guards and connectors). Start and end are guards. For each
   sample in turn, the guards it sees (line of sight: every voxel the segment traverses,
   3-D DDA, has distance ``> resolution``; at most 3 are looked for, in creation order):
   none -> the sample becomes a new guard; exactly two -> it may connect them, unless a
   connector between the same two guards is *equivalent* (the paths ``g1 -> c -> g2`` and
   ``g1 -> sample -> g2`` deform into each other, see 5.); then the shorter of the two
   stays (the connector moves to the sample if that is shorter). Nodes other than start and
   end with fewer than two neighbours are pruned, repeatedly.
3. **Paths.** Depth-first search start -> end over the roadmap (neighbours in creation
   order), stopping at ``max_raw_paths`` (300); the ``keep_raw_paths`` (25) with the fewest
   nodes are kept.
4. **Shortcut.** Each path is discretised every voxel; walking along it, a point stays
   hidden behind the last kept point while visible from it; at the first point that is not,
   the blocking voxel (pushed one voxel away from the obstacle, perpendicular to the
   sight line, along the ESDF gradient) becomes the next kept point.
5. **Equivalence.** Two paths are topologically equivalent when the points at equal
   fractions of their lengths (``ceil(max length / resolution)`` pairs) all see each other
   (no traversed voxel with distance ``<= 0``); of each equivalence class the first path is
   kept.
6. **Selection.** The shortest path, then in order of length up to ``reserve_num`` (6) in
   all, as long as they are shorter than ``ratio_to_short`` (5.5) times the shortest. Each
   is joined to the segment's points before start and after end, shortcut again (up to
   5 passes, stopping when a pass does not shorten it), and the equivalence pruning
   repeats.

Differences from the original, all deliberate:

- Sampling stops at ``max_samples`` draws only; the original also stops after 5 ms of
  sampling (a wall-clock cap, which would make the result depend on the host CPU).
- Line of sight walks the voxels of the segment exactly (3-D DDA); the original steps a
  voxel ray caster from the first point. Same voxels up to ties at voxel corners.
- The shortcut keeps a path collision-free: a pass whose result has a segment through an
  occupied voxel (the pushed point can still lie inside an inflated obstacle at a corner)
  is replaced by the plain greedy shortcut (the last visible discretised point becomes the
  next kept point), which cannot cross an occupied voxel if the input does not.
- The depth-first search also stops after ``max_dfs_expansions`` node expansions (a guard
  against exponential searches in dense roadmaps; the original has none).
- Consecutive duplicate points (the joins between the segment's points and the path) are
  merged; the original keeps zero-length pieces.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numba import njit

from ft_sitl.navigation.maps.esdf import (
    EsdfGrid,
    as_path,
    blocked,
    coarse_distance,
    path_free,
    trilinear,
)

__all__ = [
    "TopoParams", "TopoSearch", "collision_range", "discretize_path",
    "find_topo_paths", "path_length", "prune_equivalent", "same_topo_path", "shortcut_path",
]

@njit(cache=True)
def _length(path):
    s = 0.0
    for i in range(path.shape[0] - 1):
        s += math.sqrt((path[i + 1, 0] - path[i, 0]) ** 2 + (path[i + 1, 1] - path[i, 1]) ** 2
                       + (path[i + 1, 2] - path[i, 2]) ** 2)
    return s


@njit(cache=True)
def _discretize_n(path, n):
    """``n`` points at equal arc-length steps along the polyline (ends included)."""
    m = path.shape[0]
    cum = np.zeros(m)
    for i in range(m - 1):
        cum[i + 1] = cum[i] + math.sqrt((path[i + 1, 0] - path[i, 0]) ** 2
                                        + (path[i + 1, 1] - path[i, 1]) ** 2
                                        + (path[i + 1, 2] - path[i, 2]) ** 2)
    out = np.empty((n, 3))
    total = cum[m - 1]
    j = 0
    for k in range(n):
        s = total * k / (n - 1) if n > 1 else 0.0
        while j < m - 2 and cum[j + 1] < s:
            j += 1
        seg = cum[j + 1] - cum[j] if m > 1 else 0.0
        lam = (s - cum[j]) / seg if seg > 1e-12 else 0.0
        lam = min(max(lam, 0.0), 1.0)
        for d in range(3):
            out[k, d] = path[j, d] + lam * (path[min(j + 1, m - 1), d] - path[j, d])
    return out


@njit(cache=True)
def _discretize_res(path, res):
    """Every piece cut into ``ceil(length / res)`` equal steps; joins not repeated, pieces of
    zero length skipped."""
    m = path.shape[0]
    count = 1
    for i in range(m - 1):
        ln = math.sqrt((path[i + 1, 0] - path[i, 0]) ** 2 + (path[i + 1, 1] - path[i, 1]) ** 2
                       + (path[i + 1, 2] - path[i, 2]) ** 2)
        count += int(math.ceil(ln / res))
    out = np.empty((count, 3))
    out[0] = path[0]
    k = 1
    for i in range(m - 1):
        ln = math.sqrt((path[i + 1, 0] - path[i, 0]) ** 2 + (path[i + 1, 1] - path[i, 1]) ** 2
                       + (path[i + 1, 2] - path[i, 2]) ** 2)
        ns = int(math.ceil(ln / res))
        for j in range(1, ns + 1):
            f = j / ns
            for d in range(3):
                out[k, d] = path[i, d] + f * (path[i + 1, d] - path[i, d])
            k += 1
    return out[:k]


@njit(cache=True)
def _same_topo(p1, p2, fld, origin, res, lo, hi, thresh):
    """Fast-Planner's ``sameTopoPath``: points at equal length fractions see each other."""
    n = int(math.ceil(max(_length(p1), _length(p2)) / res))
    if n < 2:
        n = 2
    a = _discretize_n(p1, n)
    b = _discretize_n(p2, n)
    pc = np.empty(3)
    for i in range(n):
        if blocked(fld, origin, res, lo, hi, a[i], b[i], thresh, pc):
            return False
    return True


@njit(cache=True)
def _shortcut_push(dis, fld, origin, res, lo, hi):
    """One pass of Fast-Planner's visibility shortcut over the discretised path ``dis``."""
    n = dis.shape[0]
    out = np.empty((n + 1, 3))
    out[0] = dis[0]
    k = 1
    pc = np.empty(3)
    g = np.empty(3)
    for i in range(1, n):
        if not blocked(fld, origin, res, lo, hi, out[k - 1], dis[i], res, pc):
            continue
        trilinear(fld, origin, res, pc, g)
        gn = math.sqrt(g[0] * g[0] + g[1] * g[1] + g[2] * g[2])
        if gn > 1e-3:
            dvec = dis[i] - out[k - 1]
            dn = math.sqrt(dvec[0] ** 2 + dvec[1] ** 2 + dvec[2] ** 2)
            if dn > 1e-12:
                dvec /= dn
            g /= gn
            push = g - (g[0] * dvec[0] + g[1] * dvec[1] + g[2] * dvec[2]) * dvec
            pn = math.sqrt(push[0] ** 2 + push[1] ** 2 + push[2] ** 2)
            if pn > 1e-12:
                for d in range(3):
                    pc[d] += res * push[d] / pn
        out[k] = pc
        k += 1
    out[k] = dis[n - 1]
    return out[:k + 1]


@njit(cache=True)
def _shortcut_greedy(dis, fld, origin, res, lo, hi):
    """The last visible discretised point becomes the next kept point (line of sight with
    threshold 0). Returns an empty array if ``dis`` itself is blocked somewhere."""
    n = dis.shape[0]
    out = np.empty((n, 3))
    out[0] = dis[0]
    k = 1
    anchor = 0
    last_ok = 0
    pc = np.empty(3)
    i = 1
    while i < n:
        if not blocked(fld, origin, res, lo, hi, dis[anchor], dis[i], 0.0, pc):
            last_ok = i
            i += 1
            continue
        if last_ok == anchor:
            return np.empty((0, 3))
        anchor = last_ok
        out[k] = dis[anchor]
        k += 1
    if n > 1:
        out[k] = dis[n - 1]
        k += 1
    return out[:k]


@njit(cache=True)
def _build_graph(samples, start, end, clearance, fld, origin, res, lo, hi):
    """The guard/connector roadmap (module docstring, step 2). Returns positions (K, 3),
    kind (K,) 0 guard / 1 connector, the two guards of each connector (K, 2; -1 for
    guards), and the number of samples with enough clearance."""
    m = samples.shape[0]
    pos = np.empty((m + 2, 3))
    kind = np.zeros(m + 2, np.int64)
    link = -np.ones((m + 2, 2), np.int64)
    pos[0] = start
    pos[1] = end
    n = 2
    vis = np.empty(3, np.int64)
    pc = np.empty(3)
    p1 = np.empty((3, 3))
    p2 = np.empty((3, 3))
    valid = 0
    for s in range(m):
        p = samples[s]
        if coarse_distance(fld, origin, res, lo, hi, p) <= clearance:
            continue
        valid += 1
        nv = 0
        for g in range(n):
            if kind[g] != 0:
                continue
            if not blocked(fld, origin, res, lo, hi, p, pos[g], res, pc):
                vis[nv] = g
                nv += 1
                if nv > 2:
                    break
        if nv == 0:
            pos[n] = p
            n += 1
        elif nv == 2:
            g1, g2 = vis[0], vis[1]
            need = True
            for c in range(n):
                if kind[c] != 1:
                    continue
                if not ((link[c, 0] == g1 and link[c, 1] == g2)
                        or (link[c, 0] == g2 and link[c, 1] == g1)):
                    continue
                p1[0] = pos[g1]
                p1[1] = p
                p1[2] = pos[g2]
                p2[0] = pos[g1]
                p2[1] = pos[c]
                p2[2] = pos[g2]
                if _same_topo(p1, p2, fld, origin, res, lo, hi, 0.0):
                    if _length(p1) < _length(p2):
                        pos[c] = p
                    need = False
                    break
            if need:
                pos[n] = p
                kind[n] = 1
                link[n, 0] = g1
                link[n, 1] = g2
                n += 1
    return pos[:n].copy(), kind[:n].copy(), link[:n].copy(), valid


# ---------------------------------------------------------------------------------------
# path utilities
# ---------------------------------------------------------------------------------------
def path_length(path) -> float:
    return float(_length(as_path(path)))


def discretize_path(path, n: int) -> np.ndarray:
    """``n >= 2`` points at equal arc-length steps along the polyline (Fast-Planner's
    ``discretizePath(path, pt_num)``)."""
    if n < 2:
        raise ValueError(f"n must be >= 2, got {n}")
    return _discretize_n(as_path(path), int(n))


def _dedupe(path: np.ndarray) -> np.ndarray:
    keep = np.ones(len(path), dtype=bool)
    keep[1:] = np.linalg.norm(np.diff(path, axis=0), axis=1) > 1e-9
    return path[keep]


def same_topo_path(path1, path2, grid: EsdfGrid, thresh: float = 0.0) -> bool:
    """Topological equivalence (module docstring, step 5)."""
    return bool(_same_topo(as_path(path1), as_path(path2), *grid.kernel_args(), float(thresh)))


def shortcut_path(path, grid: EsdfGrid, iterations: int = 1) -> np.ndarray:
    """Fast-Planner's visibility shortcut, ``iterations`` passes, each kept only if it does
    not lengthen the path; a pass that would cross an occupied voxel falls back to the
    greedy shortcut (module docstring). A path that is itself blocked comes back as it is
    when no pass can shorten it safely."""
    short = _dedupe(as_path(path))
    args = grid.kernel_args()
    for _ in range(int(iterations)):
        if short.shape[0] < 2:
            break
        last = short
        dis = _discretize_res(short, grid.resolution)
        if dis.shape[0] < 2:
            break
        cand = _dedupe(_shortcut_push(dis, *args))
        if not path_free(cand, *args, 0.0):
            cand = _shortcut_greedy(dis, *args)
            if cand.shape[0] == 0:
                short = last
                break
            cand = _dedupe(cand)
        short = cand
        if _length(short) > _length(last):
            short = last
            break
    return short


def prune_equivalent(paths: list[np.ndarray], grid: EsdfGrid) -> list[np.ndarray]:
    """Keep the first path of each topological equivalence class (in the given order)."""
    kept: list[np.ndarray] = []
    args = grid.kernel_args()
    for p in paths:
        if not any(_same_topo(p, q, *args, 0.0) for q in kept):
            kept.append(p)
    return kept


# ---------------------------------------------------------------------------------------
# the search
# ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class TopoParams:
    """``TopologyPRM`` parameters (Fast-Planner's ``topo_replan`` launch values)."""

    sample_inflate: tuple[float, float, float] = (1.0, 3.5, 1.0)  # m: box = (L/2, 0, 0) + this
    clearance: float = 0.3  # m: samples need a larger distance; also the collision range's
    max_samples: int = 2000
    max_raw_paths: int = 300
    keep_raw_paths: int = 25  # max_raw_path2: the raw paths with the fewest nodes kept
    reserve_num: int = 6
    ratio_to_short: float = 5.5
    select_shortcut_passes: int = 5  # shortcut passes after joining the segment's points
    max_dfs_expansions: int = 200_000

    def __post_init__(self):
        infl = tuple(float(v) for v in self.sample_inflate)
        if len(infl) != 3 or not all(math.isfinite(v) and v >= 0 for v in infl):
            raise ValueError(f"TopoParams.sample_inflate must be 3 numbers >= 0, got {infl}")
        object.__setattr__(self, "sample_inflate", infl)
        if not (math.isfinite(self.clearance) and self.clearance >= 0):
            raise ValueError(f"TopoParams.clearance must be >= 0, got {self.clearance!r}")
        if not self.ratio_to_short >= 1.0:
            raise ValueError(f"TopoParams.ratio_to_short must be >= 1, got "
                             f"{self.ratio_to_short!r}")
        for name in ("max_samples", "max_raw_paths", "keep_raw_paths", "reserve_num",
                     "select_shortcut_passes", "max_dfs_expansions"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ValueError(f"TopoParams.{name} must be a positive integer, got {v!r}")


@dataclass(eq=False)
class TopoSearch:
    """What :func:`find_topo_paths` found: the roadmap, the raw, shortcut, filtered and
    selected paths (the selected ones joined to the segment's points)."""

    nodes: np.ndarray  # (K, 3) positions; 0 = start, 1 = end
    kinds: np.ndarray  # (K,) 0 guard, 1 connector
    alive: np.ndarray  # (K,) bool: kept by the pruning
    edges: list[tuple[int, int]]  # (guard, connector) pairs between kept nodes
    valid_samples: int
    raw_paths: list[np.ndarray] = field(default_factory=list)
    short_paths: list[np.ndarray] = field(default_factory=list)
    filtered_paths: list[np.ndarray] = field(default_factory=list)
    paths: list[np.ndarray] = field(default_factory=list)
    dfs_expansions: int = 0


def _sample_frame(start: np.ndarray, end: np.ndarray) -> np.ndarray:
    x = end - start
    n = float(np.linalg.norm(x))
    x = x / n if n > 1e-9 else np.array([1.0, 0.0, 0.0])
    y = np.cross(x, np.array([0.0, 0.0, -1.0]))
    if np.linalg.norm(y) < 1e-6:  # a vertical segment: any horizontal y
        y = np.array([0.0, 1.0, 0.0])
    y /= np.linalg.norm(y)
    z = np.cross(x, y)
    return np.column_stack([x, y, z])


def _prune_graph(n: int, kinds: np.ndarray, link: np.ndarray) -> np.ndarray:
    """Alive mask after repeatedly removing nodes (not start/end) with < 2 neighbours."""
    alive = np.ones(n, dtype=bool)
    while True:
        deg = np.zeros(n, dtype=np.int64)
        conn = np.flatnonzero(alive & (kinds == 1))
        for c in conn:
            for g in link[c]:
                if alive[g]:
                    deg[c] += 1
                    deg[g] += 1
        drop = alive & (deg <= 1)
        drop[:2] = False
        if not drop.any():
            return alive
        alive &= ~drop


def _dfs(neighbours: list[list[int]], max_paths: int, max_expansions: int):
    """Fast-Planner's depth-first enumeration of node sequences 0 -> ... -> 1."""
    paths: list[list[int]] = []
    expansions = 0
    vis = [0]
    on_path = {0}
    stack = [0]  # next neighbour index to try, per node on the path
    # entering the start: record a direct path if the end is a neighbour
    if 1 in neighbours[0]:
        paths.append([0, 1])
    while stack and len(paths) < max_paths and expansions < max_expansions:
        cur = vis[-1]
        k = stack[-1]
        nbs = neighbours[cur]
        if k >= len(nbs):
            stack.pop()
            on_path.discard(vis.pop())
            continue
        stack[-1] = k + 1
        nb = nbs[k]
        if nb == 1 or nb in on_path:
            continue
        vis.append(nb)
        on_path.add(nb)
        stack.append(0)
        expansions += 1
        if 1 in neighbours[nb]:
            paths.append(vis + [1])
    return paths[:max_paths], expansions


def find_topo_paths(start, end, start_pts, end_pts, grid: EsdfGrid,
                    rng: np.random.Generator, params: TopoParams | None = None) -> TopoSearch:
    """Fast-Planner's ``findTopoPaths`` (module docstring): distinct paths start -> end,
    each joined to ``start_pts`` (before) and ``end_pts`` (after) in ``TopoSearch.paths``."""
    p = params if params is not None else TopoParams()
    s = np.asarray(start, dtype=float).reshape(3)
    e = np.asarray(end, dtype=float).reshape(3)
    sp = np.asarray(start_pts, dtype=float).reshape(-1, 3)
    ep = np.asarray(end_pts, dtype=float).reshape(-1, 3)
    args = grid.kernel_args()

    # 1.-2. samples and roadmap
    half = np.array([0.5 * float(np.linalg.norm(e - s)) + p.sample_inflate[0],
                     p.sample_inflate[1], p.sample_inflate[2]])
    rot = _sample_frame(s, e)
    unit = rng.uniform(-1.0, 1.0, size=(p.max_samples, 3))
    samples = np.ascontiguousarray((unit * half) @ rot.T + 0.5 * (s + e))
    pos, kinds, link, valid = _build_graph(samples, s, e, float(p.clearance), *args)
    n = pos.shape[0]
    alive = _prune_graph(n, kinds, link)
    neighbours: list[list[int]] = [[] for _ in range(n)]
    edges = []
    for c in range(n):
        if kinds[c] == 1 and alive[c] and alive[link[c, 0]] and alive[link[c, 1]]:
            g1, g2 = int(link[c, 0]), int(link[c, 1])
            neighbours[g1].append(c)
            neighbours[g2].append(c)
            neighbours[c] = [g1, g2]
            edges += [(g1, c), (g2, c)]
    out = TopoSearch(nodes=pos, kinds=kinds, alive=alive, edges=edges, valid_samples=int(valid))

    # 3. paths by DFS, the ones with the fewest nodes first
    seqs, out.dfs_expansions = _dfs(neighbours, p.max_raw_paths, p.max_dfs_expansions)
    seqs = sorted(seqs, key=len)[:p.keep_raw_paths]  # stable: DFS order within a count
    out.raw_paths = [pos[np.array(q)] for q in seqs]
    if not out.raw_paths:
        return out

    # 4.-5. shortcut, prune equivalent
    out.short_paths = [shortcut_path(q, grid, 1) for q in out.raw_paths]
    out.filtered_paths = prune_equivalent(out.short_paths, grid)

    # 6. select short ones, join the segment, shortcut again, prune again
    pool = list(out.filtered_paths)
    lengths = [path_length(q) for q in pool]
    chosen: list[np.ndarray] = []
    min_len = None
    while pool and len(chosen) < p.reserve_num:
        k = int(np.argmin(lengths))
        if min_len is None:
            min_len = max(lengths[k], 1e-9)
        elif lengths[k] / min_len >= p.ratio_to_short:
            break
        chosen.append(pool.pop(k))
        lengths.pop(k)
    joined = [shortcut_path(_dedupe(np.vstack([sp, q, ep])), grid, p.select_shortcut_passes)
              for q in chosen]
    out.paths = prune_equivalent(joined, grid)
    return out


# ---------------------------------------------------------------------------------------
# the colliding stretch of a local segment
# ---------------------------------------------------------------------------------------
def collision_range(spline, grid: EsdfGrid, clearance: float = 0.3, step_s: float = 0.05):
    """Fast-Planner's ``findCollisionRange`` on a B-spline segment: the curve sampled every
    ``step_s`` seconds; a sample is unsafe when its coarse distance is ``< clearance``.

    Returns ``(colli_start, colli_end, start_pts, end_pts)``: the last safe sample before
    each unsafe run, the first safe sample after each (lists of points); the curve from its
    start to the first run's start point, and from the last exit to its end, sampled at
    most one knot span apart (arrays). When the curve never comes closer than
    ``clearance``, ``colli_start`` is empty; when it ends in the unsafe region after a
    single run, ``colli_end`` is empty (the original then replans nothing).
    """
    dur = spline.duration
    ts = np.arange(0.0, dur + 1e-4, step_s)
    pts = spline.position(ts)
    safe = grid.distance(pts) >= clearance
    colli_start: list[np.ndarray] = []
    colli_end: list[np.ndarray] = []
    t_s = t_e = None
    last_safe = True
    for k, tc in enumerate(ts):
        if last_safe and not safe[k]:
            tb = max(tc - step_s, 0.0)
            colli_start.append(spline.position(tb))
            if t_s is None:
                t_s = tb
        elif not last_safe and safe[k]:
            colli_end.append(pts[k])
            t_e = tc
        last_safe = bool(safe[k])
    if not colli_start or (len(colli_start) == 1 and not colli_end):
        return colli_start, colli_end, np.zeros((0, 3)), np.zeros((0, 3))
    dt = spline.dt
    sn = max(int(math.ceil(t_s / dt - 1e-9)), 1)
    start_pts = spline.position(np.linspace(0.0, t_s, sn + 1))
    sn = max(int(math.ceil((dur - t_e) / dt - 1e-9)), 1)
    end_pts = spline.position(np.linspace(t_e, dur, sn + 1))
    return colli_start, colli_end, start_pts, end_pts
