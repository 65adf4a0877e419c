"""Fast-Planner's kinodynamic A*: a search over (position, velocity) with double-integrator
motion primitives, ending in an analytic one-shot to the goal.

Behaviour and defaults follow Fast-Planner's ``KinodynamicAstar`` with its
``kino_algorithm.xml`` parameters (docs/planner-facts.md); the code is our own.

State and primitives. A node holds ``x = (p, v)`` (world ENU, m and m/s). A primitive
applies a constant acceleration ``u`` for ``tau`` seconds::

    p(t) = p + v t + u t^2 / 2,    v(t) = v + u t

Every expansion tries the 125 inputs ``{-a, -a/2, 0, a/2, a}^3`` (``a`` = ``max_acc``) for
``tau = max_tau`` (0.6 s). The first expansion of a search started with
``keep_start_acc`` instead keeps the current acceleration for ``k * init_max_tau / 20``
seconds, ``k = 1..20`` (up to 0.8 s), so the path continues the flown trajectory smoothly.
Like Fast-Planner's planner manager, :meth:`KinodynamicAstar.search` retries once with the
full input set when that first search finds no path (e.g. when hovering, every
keep-the-acceleration child stays in the start voxel and is pruned).

A child is dropped when its end velocity exceeds ``max_vel`` on any axis, when any of its
``check_num`` (5) points at ``tau k / check_num`` is occupied or outside the bounds, when it
ends in its parent's voxel, or when its voxel is already closed. Children of one parent
that end in the same voxel keep the lowest ``f``; a child reaching a voxel already open
replaces that node when its ``g`` is lower (both as the original). Between check points
(``tau / 5`` apart: up to 0.36 m per axis at 3 m/s) a primitive can graze a corner or cross
a wall thinner than that, as in the original; Fast-Planner's B-spline stage (ESDF) and its
trajectory checks deal with that.

Cost. ``g += (||u||^2 + w_time) tau`` (``w_time`` = rho = 10): control effort plus time.
The heuristic is ``lambda_heu`` (5) times the cost of the two-point boundary value problem
(OBVP) from the node to the goal state: the cubic minimising ``int ||a||^2 dt + w_time T``
costs ::

    J(T) = 12 |dp|^2 / T^3 - 12 (v0 + v1).dp / T^2 + 4 (|v0|^2 + v0.v1 + |v1|^2) / T + w_time T

and its stationary points are the positive roots of the quartic
``w_time T^4 + c3 T^2 + c2 T + c1`` (Fast-Planner solves the same quartic). ``T`` is
restricted to ``T >= max_i |dp_i| / (max_vel / 2)`` as in the original; ``J`` is evaluated
at the roots above that bound and at the bound itself, and the least is taken.

Closed set ("state voxels"). As Fast-Planner in its static-environment mode, nodes are
hashed by their position voxel only (``resolution``, 0.1 m, counted from the lower bound
corner, or from the world origin without bounds): one node per voxel, whatever its
velocity; time is not binned (the original bins time, 0.8 s, only in its dynamic-obstacle
mode, which the benchmark does not use).

Termination (checked on the node taken from the open set). The node has reached the
horizon when it is ``horizon`` (7 m) or farther from the start; it is near the goal when
its voxel is within ``ceil(goal_tolerance / resolution)`` voxels of the goal's voxel on
every axis (the original's 1 m box). Near the goal a one-shot cubic (the OBVP solution with
the heuristic's ``T``) is tried: it is accepted when 10 points along it are free and
inside the bounds and (our addition, ``shot_check_vel``, default on) its velocity stays
within ``max_vel`` on every axis; ``shot_check_acc`` (default off) also bounds its
acceleration. Statuses, as the original's return codes:

- ``REACHED_GOAL``: the shot succeeded (the trajectory ends exactly at the goal state);
- ``REACHED_HORIZON``: the node is at the horizon and no shot succeeded;
- ``NEAR_GOAL``: near the goal but the shot failed; the path ends at that node;
- ``NO_PATH``: the open set ran empty, a cap was hit, or the start itself is near the goal
  and the shot from it failed (the original returns NO_PATH there too).

Caps: ``max_expansions`` per search attempt (ours) and ``max_nodes`` (the original's
``allocate_num``) keep the search deterministic; ``max_time_s`` (off by default) adds a
wall-clock limit over both attempts, checked after each occupancy query (every 256
expansions with a voxel grid).

Implementation: the search loop is one numba kernel over reused arrays (node pool,
open-addressing voxel hash that doubles when half full, indexed binary heap). With an
``occupied`` callable it returns to Python once per expansion to ask about that
expansion's collision-check points (one call, up to 125 x 5 points); with a
:class:`VoxelOccupancy` grid it reads the grid itself and runs without returning. The shot
is tried in Python at the end.

Differences from the original, on purpose:
- the open set is an indexed binary heap ordered by (f, node number): a node whose score
  changes is moved to its place (the original edits the score in place inside its
  ``std::priority_queue`` without re-heaping, so its pop order is slightly off);
- bounds are checked at every collision-check point, not only at the child's end state;
- the shot's velocity is checked (the original has its velocity and acceleration checks
  commented out), exactly on the cubic (velocity is quadratic in time), not at samples.
  Acceleration is not checked by default: nodes reach the 1 m goal box at speed, so most
  shots brake harder than ``max_acc`` and checking it turns most arrivals into
  NEAR_GOAL; Fast-Planner leaves acceleration to the B-spline stage;
- the heuristic is ``lambda_heu x J``. The original multiplies by a further
  ``1 + tie_breaker`` (~2.0001), i.e. an effective weight of ~10; pass
  ``lambda_heu=10.0005`` to reproduce that;
- :meth:`KinoResult.bspline_samples` returns the last node's velocity as the end velocity
  when no shot was taken (the original returns the start's, a slip).
"""

from __future__ import annotations

import enum
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numba import njit

OccupancyFn = Callable[[np.ndarray], np.ndarray]

# voxel-index packing into one int64 key: 21 bits per axis, offset to make them positive
_KEY_BITS = 21
_KEY_OFFSET = 1 << (_KEY_BITS - 1)
_INIT_STEPS = 20  # the first expansion's durations: init_max_tau * k / 20, k = 1..20
_ACC_LEVELS = (-1.0, -0.5, 0.0, 0.5, 1.0)  # the input set per axis, times max_acc
_SHOT_CHECK_NUM = 10
_NO_GRID = np.zeros((1, 1, 1), np.uint8)  # stands in for the grid when a callable is used


class KinoStatus(enum.Enum):
    REACHED_GOAL = "reached_goal"
    REACHED_HORIZON = "reached_horizon"
    NEAR_GOAL = "near_goal"
    NO_PATH = "no_path"


@dataclass(frozen=True)
class KinoAstarParams:
    """Search parameters; defaults are Fast-Planner's ``kino_algorithm.xml``.

    ``max_vel``/``max_acc`` are Fast-Planner's defaults (3 m/s, 2 m/s^2); a benchmark
    navigator passes the benchmark's speed cap (4 m/s).
    """

    max_vel: float = 3.0  # m/s, per axis (search/max_vel)
    max_acc: float = 2.0  # m/s^2, per axis: the input set is {-a, -a/2, 0, a/2, a}^3
    max_tau: float = 0.6  # s, duration of a primitive (search/max_tau)
    init_max_tau: float = 0.8  # s, longest keep-the-acceleration first primitive
    w_time: float = 10.0  # rho, cost per second of flight (search/w_time)
    lambda_heu: float = 5.0  # heuristic weight (search/lambda_heu)
    horizon: float = 7.0  # m from the start where the search stops (search/horizon)
    check_num: int = 5  # collision-check points per primitive (search/check_num)
    goal_tolerance: float = 1.0  # m, per axis, where the one-shot is tried (ceil(1/res) voxels)
    shot_check_vel: bool = True  # reject a shot exceeding max_vel on an axis
    shot_check_acc: bool = False  # reject a shot exceeding max_acc on an axis
    max_nodes: int = 100_000  # node pool size (search/allocate_num)
    max_expansions: int = 10_000  # expansions per search attempt (ours)
    max_time_s: float | None = None  # wall-clock cap over a whole search (None: none)
    retry_full_inputs: bool = True  # planner manager: retry without the start acceleration

    def __post_init__(self):
        for name in ("max_vel", "max_acc", "max_tau", "init_max_tau", "w_time", "horizon",
                     "goal_tolerance"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) \
                    or v <= 0:
                raise ValueError(f"{name}: must be a positive number, got {v!r}")
            object.__setattr__(self, name, float(v))
        if isinstance(self.lambda_heu, bool) or not isinstance(self.lambda_heu, (int, float)) \
                or not math.isfinite(self.lambda_heu) or self.lambda_heu < 0:
            raise ValueError(f"lambda_heu: must be a number >= 0, got {self.lambda_heu!r}")
        object.__setattr__(self, "lambda_heu", float(self.lambda_heu))
        for name in ("check_num", "max_nodes", "max_expansions"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ValueError(f"{name}: must be a positive integer, got {v!r}")
        if self.max_time_s is not None and not (
                isinstance(self.max_time_s, (int, float)) and not isinstance(self.max_time_s, bool)
                and math.isfinite(self.max_time_s) and self.max_time_s > 0):
            raise ValueError(f"max_time_s: must be a positive number or None, "
                             f"got {self.max_time_s!r}")


@dataclass(frozen=True)
class TrajectorySamples:
    """A trajectory sampled at times ``t`` (s from its start): positions, velocities,
    accelerations, each ``(n, 3)``."""

    t: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray


@dataclass(frozen=True, eq=False)
class KinoResult:
    """What a search returns.

    ``states`` (K+1, 6) are the node states from the start to the path's last node, reached
    by ``inputs`` (K, 3) held for ``durations`` (K,). With ``REACHED_GOAL`` the path goes on
    with the shot: ``shot_coeffs`` (4, 3) = (p0, v0, b, c) of ``p(t) = p0 + v0 t + b t^2 +
    c t^3`` for ``shot_duration`` seconds. ``NO_PATH`` has K = 0 and no shot.
    """

    status: KinoStatus
    start_state: np.ndarray
    goal_state: np.ndarray
    states: np.ndarray
    inputs: np.ndarray
    durations: np.ndarray
    shot_coeffs: np.ndarray | None
    shot_duration: float
    expansions: int  # over all attempts
    nodes: int  # nodes created over all attempts
    search_time_s: float
    attempts: int  # 1, or 2 when the keep-the-acceleration search was retried
    kept_start_acc: bool  # whether the returned path's first primitive kept the start acc
    stop_reason: str  # goal, horizon, near_goal, exhausted, expansion_cap, node_cap,
    # time_cap, start_shot_failed
    stats: dict = field(default_factory=dict)

    @property
    def found(self) -> bool:
        return self.status is not KinoStatus.NO_PATH

    @property
    def duration(self) -> float:
        return float(self.durations.sum()) + self.shot_duration

    @property
    def end_state(self) -> np.ndarray:
        """The state where the trajectory ends (the goal state after a shot)."""
        if self.shot_coeffs is not None:
            p, v, _ = _cubic_eval(self.shot_coeffs, np.array([self.shot_duration]))
            return np.concatenate([p[0], v[0]])
        return self.states[-1].copy()

    def sample(self, dt: float) -> TrajectorySamples:
        """Sample the whole trajectory (primitives, then the shot) every ``dt`` seconds from
        its start; the end point is always included."""
        if not (math.isfinite(dt) and dt > 0):
            raise ValueError(f"dt: must be a positive number of seconds, got {dt!r}")
        total = self.duration
        n = int(math.floor(total / dt + 1e-9))
        t = np.arange(n + 1) * dt
        if total - t[-1] > 1e-9:
            t = np.append(t, total)
        return self.evaluate(t)

    def evaluate(self, t: np.ndarray) -> TrajectorySamples:
        """Position, velocity, acceleration at times ``t`` (clipped to [0, duration])."""
        t = np.clip(np.asarray(t, dtype=float), 0.0, self.duration)
        pos = np.empty((t.size, 3))
        vel = np.empty((t.size, 3))
        acc = np.empty((t.size, 3))
        ends = np.cumsum(self.durations)
        k_prims = len(self.durations)
        t_prims = float(ends[-1]) if k_prims else 0.0
        if self.shot_coeffs is not None:
            seg = np.searchsorted(ends, t, side="left") if k_prims else np.zeros(t.size, int)
            in_shot = (t > t_prims) | (seg >= k_prims)
        else:
            seg = np.minimum(np.searchsorted(ends, t, side="left"), max(k_prims - 1, 0))
            in_shot = np.zeros(t.size, bool)
        if k_prims:
            m = ~in_shot
            s = seg[m]
            start_t = np.concatenate([[0.0], ends[:-1]])[s]
            tau = (t[m] - start_t)[:, None]
            x0 = self.states[s]
            u = self.inputs[s]
            pos[m] = x0[:, :3] + x0[:, 3:] * tau + 0.5 * u * tau**2
            vel[m] = x0[:, 3:] + u * tau
            acc[m] = u
        elif self.shot_coeffs is None:  # no path: the start state only
            pos[:] = self.states[0, :3]
            vel[:] = self.states[0, 3:]
            acc[:] = 0.0
        if self.shot_coeffs is not None and in_shot.any():
            p, v, a = _cubic_eval(self.shot_coeffs, t[in_shot] - t_prims)
            pos[in_shot], vel[in_shot], acc[in_shot] = p, v, a
        return TrajectorySamples(t, pos, vel, acc)

    def bspline_samples(self, ts: float):
        """Points for fitting a uniform B-spline, as Fast-Planner's ``getSamples``: the
        duration is cut into ``max(8, floor(T / ts))`` equal spans; returns
        ``(ts_used, points (n+1, 3), start_vel, end_vel, start_acc, end_acc)``."""
        if not self.found:
            raise ValueError("no path to sample")
        if not (math.isfinite(ts) and ts > 0):
            raise ValueError(f"ts: must be a positive number of seconds, got {ts!r}")
        total = self.duration
        seg_num = max(8, int(math.floor(total / ts)))
        ts_used = total / seg_num
        points = self.evaluate(np.arange(seg_num + 1) * ts_used).position
        start_vel = self.start_state[3:].copy()
        if len(self.durations):
            start_acc = self.inputs[0].copy()
        else:
            start_acc = 2.0 * self.shot_coeffs[2]
        if self.shot_coeffs is not None:
            _, v, a = _cubic_eval(self.shot_coeffs, np.array([self.shot_duration]))
            end_vel, end_acc = self.goal_state[3:].copy(), a[0]
        else:
            end_vel, end_acc = self.states[-1, 3:].copy(), self.inputs[-1].copy()
        return ts_used, points, start_vel, end_vel, start_acc, end_acc


# --- compiled kernels -----------------------------------------------------------------
# The search runs in one compiled kernel (``_advance``) that stops only when it needs the
# occupancy of new collision-check points (the map is a Python callable), when a node
# taken from the open set ends the search, or at a cap. Its state lives in plain arrays
# (a node pool, an open-addressing hash from voxel keys to nodes, an indexed binary heap).

# integer slots of the CNT array
_C_NODES, _C_HEAP, _C_EXP, _C_CUR, _C_NCAND, _C_PENDING, _C_INIT = 0, 1, 2, 3, 4, 5, 6
_C_MAXEXP, _C_MAXNODES, _C_CHECK, _C_BOUNDS, _C_TOL, _C_MASK = 7, 8, 9, 10, 11, 12
_C_NEAR, _C_HORIZON, _C_GRID, _C_MAXCH = 13, 14, 15, 16
_C_SIZE = 17
# float slots of the P array
_P_VMAX, _P_WTIME, _P_LAMBDA, _P_HORIZON, _P_INVRES, _P_GRID_INVRES = 0, 1, 2, 3, 4, 5
_P_SIZE = 6
# what _advance returns
_NEED_OCC, _TERMINAL, _EMPTY, _EXP_CAP, _NODE_CAP, _YIELD, _GROW = 1, 2, 3, 4, 5, 6, 7
_HASH_MIN = 1 << 13  # initial hash slots; doubled (_GROW) to stay at most half full
_YIELD_EVERY = 256  # grid mode: expansions between returns to Python (wall-clock checks)
_HASH_MUL = -7046029254386353131  # 0x9E3779B97F4A7C15 as a signed 64-bit integer


@njit(cache=True)
def _poly4(w, c3, c2, c1, t):
    return ((w * t * t + c3) * t + c2) * t + c1


@njit(cache=True)
def _depressed_cubic_roots(p, q):
    """Real roots of t^3 + p t + q, ascending, padded with +inf."""
    inf = np.inf
    if p == 0.0:
        return np.cbrt(-q), inf, inf
    d = (0.5 * q) ** 2 + (p / 3.0) ** 3
    if d > 0.0:
        s = math.sqrt(d)
        return np.cbrt(-0.5 * q + s) + np.cbrt(-0.5 * q - s), inf, inf
    # three real roots (p < 0 here): r cos(phi - 2 pi k / 3), k = 0, 1, 2
    r = 2.0 * math.sqrt(-p / 3.0)
    phi = math.acos(min(1.0, max(-1.0, 3.0 * q / (p * r)))) / 3.0
    t0 = r * math.cos(phi)  # the largest
    t1 = r * math.cos(phi - 2.0 * math.pi / 3.0)
    t2 = r * math.cos(phi - 4.0 * math.pi / 3.0)  # the smallest
    return t2, t1, t0


@njit(cache=True)
def _bracketed_root(w, c3, c2, c1, lo, hi):
    """The root of w t^4 + c3 t^2 + c2 t + c1 in [lo, hi] when its sign differs at the two
    ends (zero counts as positive), else -1. The caller cuts intervals where the quartic is
    monotone and of one convexity, so Newton's method started at the end where the value
    and the curvature share a sign (Fourier's condition) converges monotonically; a
    bisection safeguard keeps it inside the bracket anyway."""
    f_lo = _poly4(w, c3, c2, c1, lo)
    f_hi = _poly4(w, c3, c2, c1, hi)
    neg_lo = f_lo < 0.0
    if neg_lo == (f_hi < 0.0):
        return -1.0
    mid = 0.5 * (lo + hi)
    curv = 12.0 * w * mid * mid + 2.0 * c3
    t = lo if (f_lo > 0.0) == (curv > 0.0) else hi
    for _ in range(100):
        ft = _poly4(w, c3, c2, c1, t)
        if ft == 0.0:
            return t
        if (ft < 0.0) == neg_lo:
            lo = t
        else:
            hi = t
        d = (4.0 * w * t * t + 2.0 * c3) * t + c2
        tn = t - ft / d if d != 0.0 else 0.5 * (lo + hi)
        if not (lo <= tn <= hi):
            tn = 0.5 * (lo + hi)
        if abs(tn - t) <= 1e-15 * max(t, 1e-300) or lo >= hi:
            return tn
        t = tn
    return t


@njit(cache=True)
def _obvp_cost_at(a3, a2, a1, w, t):
    """J(T) = a3 / T^3 + a2 / T^2 + a1 / T + w T."""
    if t <= 0.0:
        if a3 == 0.0 and a2 == 0.0 and a1 == 0.0:
            return 0.0
        return np.inf
    return a3 / t**3 + a2 / t**2 + a1 / t + w * t


@njit(cache=True)
def _obvp(x0, x1, w_time, max_vel):
    """Cost and duration of the OBVP from state x0 to x1 (Fast-Planner's heuristic).

    The stationary points of J are the positive roots of the quartic
    w T^4 + c3 T^2 + c2 T + c1. The roots of its derivative (a depressed cubic, closed
    form) and its inflection point cut (0, Fujiwara's bound] into intervals where the
    quartic is monotone and of one convexity, so each holds at most one root; roots
    without a sign change (double roots) are not minima of J and are skipped."""
    dpp = 0.0
    vdp = 0.0
    vv = 0.0
    dp_inf = 0.0
    for i in range(3):
        dp = x1[i] - x0[i]
        dpp += dp * dp
        vdp += (x0[3 + i] + x1[3 + i]) * dp
        vv += x0[3 + i] * x0[3 + i] + x0[3 + i] * x1[3 + i] + x1[3 + i] * x1[3 + i]
        dp_inf = max(dp_inf, abs(dp))
    c1 = -36.0 * dpp
    c2 = 24.0 * vdp
    c3 = -4.0 * vv
    # J(T) = -c1 / (3 T^3) - c2 / (2 T^2) - c3 / T + w T
    a3 = -c1 / 3.0
    a2 = -c2 / 2.0
    a1 = -c3
    t_bar = dp_inf / (0.5 * max_vel)
    best_t = t_bar
    best = _obvp_cost_at(a3, a2, a1, w_time, t_bar)
    # Fujiwara's bound on the roots' magnitude (the quartic has no cubic term)
    bound = 2.0 * max(math.sqrt(abs(c3) / w_time), np.cbrt(abs(c2) / w_time),
                      (abs(c1) / (2.0 * w_time)) ** 0.25) + 1e-12
    t_flex = math.sqrt(-c3 / (6.0 * w_time))  # where the quartic's curvature changes sign
    if c2 <= 0.0:
        # signs + - - -: one positive root, beyond t_flex (the quartic is <= 0 there), where
        # the quartic is increasing and convex: no need for the derivative's roots
        if bound >= t_bar:
            t = _bracketed_root(w_time, c3, c2, c1, max(t_flex, t_bar), bound)
            if t >= t_bar:
                c = _obvp_cost_at(a3, a2, a1, w_time, t)
                if c < best:
                    best = c
                    best_t = t
        return best, best_t
    s0, s1, s2 = _depressed_cubic_roots(c3 / (2.0 * w_time), c2 / (4.0 * w_time))
    lo = 0.0
    for cut in (s0, s1, s2, bound):
        hi = min(cut, bound)
        if hi <= lo:
            continue
        mid = t_flex if lo < t_flex < hi else hi
        for a, b in ((lo, mid), (mid, hi)):
            if b > a and b >= t_bar:
                t = _bracketed_root(w_time, c3, c2, c1, a, b)
                if t >= t_bar:
                    c = _obvp_cost_at(a3, a2, a1, w_time, t)
                    if c < best:
                        best = c
                        best_t = t
        lo = hi
    return best, best_t


@njit(cache=True)
def _hash_find(hk, hv, key, mask):
    s = ((key * _HASH_MUL) ^ ((key * _HASH_MUL) >> 29)) & mask
    while True:
        v = hv[s]
        if v < 0:
            return -1
        if hk[s] == key:
            return v
        s = (s + 1) & mask


@njit(cache=True)
def _hash_insert(hk, hv, key, val, mask):
    s = ((key * _HASH_MUL) ^ ((key * _HASH_MUL) >> 29)) & mask
    while hv[s] >= 0:
        s = (s + 1) & mask
    hk[s] = key
    hv[s] = val
    return s


@njit(cache=True)
def _before(f, a, b):
    """Heap order: lower f first, then the older node."""
    return f[a] < f[b] or (f[a] == f[b] and a < b)


@njit(cache=True)
def _sift_up(heap, hpos, f, i):
    node = heap[i]
    while i > 0:
        up = (i - 1) >> 1
        other = heap[up]
        if not _before(f, node, other):
            break
        heap[i] = other
        hpos[other] = i
        i = up
    heap[i] = node
    hpos[node] = i


@njit(cache=True)
def _sift_down(heap, hpos, f, i, size):
    node = heap[i]
    while True:
        c = 2 * i + 1
        if c >= size:
            break
        if c + 1 < size and _before(f, heap[c + 1], heap[c]):
            c += 1
        if not _before(f, heap[c], node):
            break
        heap[i] = heap[c]
        hpos[heap[i]] = i
        i = c
    heap[i] = node
    hpos[node] = i


@njit(cache=True)
def _heap_push(heap, hpos, f, cnt, node):
    i = cnt[_C_HEAP]
    cnt[_C_HEAP] = i + 1
    heap[i] = node
    hpos[node] = i
    _sift_up(heap, hpos, f, i)


@njit(cache=True)
def _heap_pop(heap, hpos, f, cnt):
    top = heap[0]
    size = cnt[_C_HEAP] - 1
    cnt[_C_HEAP] = size
    hpos[top] = -1
    if size > 0:
        heap[0] = heap[size]
        hpos[heap[0]] = 0
        _sift_down(heap, hpos, f, 0, size)
    return top


@njit(cache=True)
def _heap_update(heap, hpos, f, cnt, node):
    _sift_up(heap, hpos, f, hpos[node])
    _sift_down(heap, hpos, f, hpos[node], cnt[_C_HEAP])


@njit(cache=True)
def _voxel_key(vox):
    key = 0
    for a in range(3):
        key = (key << _KEY_BITS) + (vox[a] + _KEY_OFFSET)
    return key


@njit(cache=True)
def _reset(cnt, slot, hv, hpos):
    """Empty the hash and the heap of the previous search (only the slots it used)."""
    for e in range(cnt[_C_NODES]):
        hv[slot[e]] = -1
        hpos[e] = -1
    cnt[_C_NODES] = 0
    cnt[_C_HEAP] = 0
    cnt[_C_EXP] = 0
    cnt[_C_PENDING] = 0
    cnt[_C_NCAND] = 0


@njit(cache=True)
def _add_root(x, g, f, u, tau, par, vox, closed, slot, hk, hv, heap, hpos, cnt, p, origin,
              x0, goal):
    h, _ = _obvp(x0, goal, p[_P_WTIME], p[_P_VMAX])
    x[0] = x0
    g[0] = 0.0
    f[0] = p[_P_LAMBDA] * h
    u[0] = 0.0
    tau[0] = 0.0
    par[0] = -1
    for a in range(3):
        vox[0, a] = int(math.floor((x0[a] - origin[a]) * p[_P_INVRES]))
    closed[0] = 0
    slot[0] = _hash_insert(hk, hv, _voxel_key(vox[0]), 0, cnt[_C_MASK])
    cnt[_C_NODES] = 1
    _heap_push(heap, hpos, f, cnt, 0)


@njit(cache=True)
def _generate(x, pvox, inputs, taus, cnt, p, origin, lo, hi, closed, hk, hv,
              ch, ch_u, ch_tau, ch_key, ch_vox, pts):
    """Children of state ``x`` passing the velocity, bound, parent-voxel and closed-set
    tests, written compactly with their check points; returns how many."""
    check = cnt[_C_CHECK]
    use_bounds = cnt[_C_BOUNDS] == 1
    vmax = p[_P_VMAX]
    inv_res = p[_P_INVRES]
    mask = cnt[_C_MASK]
    n = 0
    vox = np.empty(3, np.int64)
    for i in range(inputs.shape[0]):
        for j in range(taus.shape[0]):
            tau = taus[j]
            ok = True
            same = True
            for a in range(3):
                ua = inputs[i, a]
                pa = x[a] + x[3 + a] * tau + 0.5 * ua * tau * tau
                va = x[3 + a] + ua * tau
                if abs(va) > vmax:
                    ok = False
                ch[n, a] = pa
                ch[n, 3 + a] = va
                vox[a] = int(math.floor((pa - origin[a]) * inv_res))
                if vox[a] != pvox[a]:
                    same = False
            if not ok or same:
                continue
            key = _voxel_key(vox)
            e = _hash_find(hk, hv, key, mask)
            if e >= 0 and closed[e] == 1:
                continue
            base = n * check
            for c in range(check):
                t = tau * (c + 1) / check
                for a in range(3):
                    q = x[a] + x[3 + a] * t + 0.5 * inputs[i, a] * t * t
                    pts[base + c, a] = q
                    if use_bounds and (q <= lo[a] or q >= hi[a]):
                        ok = False
            if not ok:
                continue
            for a in range(3):
                ch_u[n, a] = inputs[i, a]
                ch_vox[n, a] = vox[a]
            ch_tau[n] = tau
            ch_key[n] = key
            n += 1
    return n


@njit(cache=True)
def _insert(nid, x, g, f, u, tau, par, vox, closed, slot, hk, hv, heap, hpos, cnt, p, goal,
            ch, ch_u, ch_tau, ch_key, ch_vox, occ):
    """Add the free children of node ``nid`` (in input order, as the original): a new voxel
    gets a node; a sibling in the same new voxel replaces it when its f is lower; a child
    in a voxel opened earlier replaces that node when its g is lower. Returns 0, or
    _NODE_CAP when the pool is full."""
    check = cnt[_C_CHECK]
    mask = cnt[_C_MASK]
    w = p[_P_WTIME]
    first_new = cnt[_C_NODES]
    for j in range(cnt[_C_NCAND]):
        hit = False
        for c in range(check):
            if occ[j * check + c]:
                hit = True
                break
        if hit:
            continue
        uu = ch_u[j, 0] ** 2 + ch_u[j, 1] ** 2 + ch_u[j, 2] ** 2
        gj = g[nid] + (uu + w) * ch_tau[j]
        e = _hash_find(hk, hv, ch_key[j], mask)
        if 0 <= e < first_new and not gj < g[e]:
            continue  # decided by g alone: the heuristic is not needed
        h, _ = _obvp(ch[j], goal, w, p[_P_VMAX])
        fj = gj + p[_P_LAMBDA] * h
        if e < 0:
            if cnt[_C_NODES] >= cnt[_C_MAXNODES]:
                return _NODE_CAP
            e = cnt[_C_NODES]
            cnt[_C_NODES] = e + 1
            slot[e] = _hash_insert(hk, hv, ch_key[j], e, mask)
            closed[e] = 0
            vox[e] = ch_vox[j]
            push = True
        elif e >= first_new:
            if not fj < f[e]:
                continue
            push = False
        else:
            if not gj < g[e]:
                continue
            push = False
        x[e] = ch[j]
        g[e] = gj
        f[e] = fj
        u[e] = ch_u[j]
        tau[e] = ch_tau[j]
        par[e] = nid
        if push:
            _heap_push(heap, hpos, f, cnt, e)
        else:
            _heap_update(heap, hpos, f, cnt, e)
    return 0


@njit(cache=True)
def _rehash(hk_old, hk, hv, slot, n, mask):
    """Insert nodes 0..n-1 (their keys read from the old table) into an empty table."""
    for e in range(n):
        slot[e] = _hash_insert(hk, hv, hk_old[slot[e]], e, mask)


@njit(cache=True)
def _grid_occupied(grid, origin, inv_res, pts, out):
    """Occupancy of points in a voxel grid; points outside it are free (unknown)."""
    nx, ny, nz = grid.shape
    for k in range(pts.shape[0]):
        i = int(math.floor((pts[k, 0] - origin[0]) * inv_res))
        j = int(math.floor((pts[k, 1] - origin[1]) * inv_res))
        m = int(math.floor((pts[k, 2] - origin[2]) * inv_res))
        out[k] = 0 <= i < nx and 0 <= j < ny and 0 <= m < nz and grid[i, j, m] != 0


@njit(cache=True)
def _advance(x, g, f, u, tau, par, vox, closed, slot, hk, hv, heap, hpos, cnt, p, origin,
             lo, hi, start, goal, goal_vox, inp_full, tau_full, inp_init, tau_init,
             ch, ch_u, ch_tau, ch_key, ch_vox, pts, occ, grid, grid_origin):
    """Run the search until it needs occupancy (_NEED_OCC, candidates' check points in
    ``pts``), a node taken from the open set ends it (_TERMINAL, node in cnt[_C_CUR]), or
    it stops (_EMPTY, _EXP_CAP, _NODE_CAP), or the hash needs more room (_GROW). With a
    voxel grid (cnt[_C_GRID]) occupancy is read here and the kernel only returns every
    _YIELD_EVERY expansions (_YIELD)."""
    if cnt[_C_PENDING] == 1:
        cnt[_C_PENDING] = 0
        code = _insert(cnt[_C_CUR], x, g, f, u, tau, par, vox, closed, slot, hk, hv, heap,
                       hpos, cnt, p, goal, ch, ch_u, ch_tau, ch_key, ch_vox, occ)
        if code != 0:
            return code
    tol = cnt[_C_TOL]
    while True:
        if cnt[_C_HEAP] == 0:
            return _EMPTY
        if 2 * (cnt[_C_NODES] + cnt[_C_MAXCH]) > cnt[_C_MASK] + 1:
            return _GROW
        nid = heap[0]
        d2 = 0.0
        near = True
        for a in range(3):
            d2 += (x[nid, a] - start[a]) ** 2
            if abs(vox[nid, a] - goal_vox[a]) > tol:
                near = False
        horizon = math.sqrt(d2) >= p[_P_HORIZON]
        if near or horizon:
            cnt[_C_CUR] = nid
            cnt[_C_NEAR] = 1 if near else 0
            cnt[_C_HORIZON] = 1 if horizon else 0
            return _TERMINAL
        if cnt[_C_EXP] >= cnt[_C_MAXEXP]:
            return _EXP_CAP
        _heap_pop(heap, hpos, f, cnt)
        closed[nid] = 1
        cnt[_C_EXP] += 1
        cnt[_C_CUR] = nid
        if cnt[_C_INIT] == 1:
            cnt[_C_INIT] = 0
            n = _generate(x[nid], vox[nid], inp_init, tau_init, cnt, p, origin, lo, hi,
                          closed, hk, hv, ch, ch_u, ch_tau, ch_key, ch_vox, pts)
        else:
            n = _generate(x[nid], vox[nid], inp_full, tau_full, cnt, p, origin, lo, hi,
                          closed, hk, hv, ch, ch_u, ch_tau, ch_key, ch_vox, pts)
        if n == 0:
            continue
        cnt[_C_NCAND] = n
        if cnt[_C_GRID] == 0:
            cnt[_C_PENDING] = 1
            return _NEED_OCC
        _grid_occupied(grid, grid_origin, p[_P_GRID_INVRES], pts[: n * cnt[_C_CHECK]], occ)
        code = _insert(nid, x, g, f, u, tau, par, vox, closed, slot, hk, hv, heap, hpos, cnt,
                       p, goal, ch, ch_u, ch_tau, ch_key, ch_vox, occ)
        if code != 0:
            return code
        if cnt[_C_EXP] % _YIELD_EVERY == 0:
            return _YIELD


# --- plain-Python helpers (also the public OBVP functions) ----------------------------


def obvp_cost(x0, x1, w_time: float = 10.0, max_vel: float = 3.0) -> tuple[float, float]:
    """Cost ``min_T J(T)`` (without the heuristic weight) and the optimal duration ``T`` of
    the two-point problem from state ``x0 = (p, v)`` to ``x1``, ``T >= max|dp| / (vmax/2)``."""
    c, t = _obvp(np.asarray(x0, dtype=float), np.asarray(x1, dtype=float), float(w_time),
                 float(max_vel))
    return float(c), float(t)


def obvp_coefficients(x0, x1, duration: float) -> np.ndarray:
    """The cubic from ``x0`` to ``x1`` in ``duration`` seconds minimising ``int ||a||^2``:
    rows (p0, v0, b, c) of ``p(t) = p0 + v0 t + b t^2 + c t^3``, shape (4, 3)."""
    x0 = np.asarray(x0, dtype=float)
    x1 = np.asarray(x1, dtype=float)
    t = float(duration)
    if not (math.isfinite(t) and t > 0):
        raise ValueError(f"duration: must be a positive number of seconds, got {duration!r}")
    p0, v0 = x0[:3], x0[3:]
    dp, v1 = x1[:3] - p0, x1[3:]
    e = dp - v0 * t  # position error of coasting
    dv = v1 - v0
    c = (-12.0 * e / t**3 + 6.0 * dv / t**2) / 6.0
    b = 0.5 * (6.0 * e / t**2 - 2.0 * dv / t)
    return np.stack([p0, v0, b, c])


def _cubic_eval(coeffs: np.ndarray, t: np.ndarray):
    t = np.asarray(t, dtype=float)[:, None]
    p0, v0, b, c = coeffs
    pos = p0 + v0 * t + b * t**2 + c * t**3
    vel = v0 + 2.0 * b * t + 3.0 * c * t**2
    acc = 2.0 * b + 6.0 * c * t
    return pos, vel, acc


def _cubic_within_limits(coeffs: np.ndarray, duration: float, max_vel: float,
                         max_acc: float, tol: float = 1e-9) -> bool:
    """Exact per-axis check of |v| <= max_vel and |a| <= max_acc on [0, duration]."""
    _, v0, b, c = coeffs
    ts = [np.zeros(3), np.full(3, duration)]
    with np.errstate(divide="ignore", invalid="ignore"):
        t_vertex = np.where(c != 0.0, -b / (3.0 * c), 0.0)  # where the acceleration is zero
    ts.append(np.clip(t_vertex, 0.0, duration))
    for t in ts:
        v = v0 + 2.0 * b * t + 3.0 * c * t**2
        if np.any(np.abs(v) > max_vel + tol):
            return False
    for t in ts[:2]:
        a = 2.0 * b + 6.0 * c * t
        if np.any(np.abs(a) > max_acc + tol):
            return False
    return True


def _primitive_set(max_acc: float, max_tau: float):
    levels = np.array(_ACC_LEVELS) * max_acc
    grid = np.stack(np.meshgrid(levels, levels, levels, indexing="ij"), axis=-1)
    return grid.reshape(-1, 3), np.array([max_tau])  # ax outer, az inner, as the original


class _Workspace:
    """The compiled search's arrays, allocated once per planner and reused: a node pool
    of ``max_nodes``, a voxel hash kept at most half full (it starts small and doubles: a
    table sized for the whole pool would spread a small search over megabytes and miss the
    caches), the heap and scratch rows for one expansion's children."""

    def __init__(self, max_nodes: int, check_num: int, max_children: int):
        n = max_nodes
        h = _HASH_MIN
        self.x = np.empty((n, 6))
        self.g = np.empty(n)
        self.f = np.empty(n)
        self.u = np.empty((n, 3))
        self.tau = np.empty(n)
        self.par = np.empty(n, np.int64)
        self.vox = np.empty((n, 3), np.int64)
        self.closed = np.zeros(n, np.uint8)
        self.slot = np.empty(n, np.int64)
        self.hk = np.empty(h, np.int64)
        self.hv = np.full(h, -1, np.int64)
        self.heap = np.empty(n, np.int64)
        self.hpos = np.full(n, -1, np.int64)
        self.cnt = np.zeros(_C_SIZE, np.int64)
        self.cnt[_C_MASK] = h - 1
        self.cnt[_C_MAXCH] = max_children
        self.ch = np.empty((max_children, 6))
        self.ch_u = np.empty((max_children, 3))
        self.ch_tau = np.empty(max_children)
        self.ch_key = np.empty(max_children, np.int64)
        self.ch_vox = np.empty((max_children, 3), np.int64)
        self.pts = np.empty((max_children * check_num, 3))
        self.occ = np.zeros(max_children * check_num, np.bool_)

    def grow_hash(self) -> None:
        h = 2 * (int(self.cnt[_C_MASK]) + 1)
        hk = np.empty(h, np.int64)
        hv = np.full(h, -1, np.int64)
        _rehash(self.hk, hk, hv, self.slot, int(self.cnt[_C_NODES]), h - 1)
        self.hk, self.hv = hk, hv
        self.cnt[_C_MASK] = h - 1

    def nodes(self):
        return (self.x, self.g, self.f, self.u, self.tau, self.par, self.vox, self.closed,
                self.slot, self.hk, self.hv, self.heap, self.hpos, self.cnt)

    def scratch(self):
        return (self.ch, self.ch_u, self.ch_tau, self.ch_key, self.ch_vox, self.pts, self.occ)


@dataclass(frozen=True, eq=False)
class VoxelOccupancy:
    """An occupancy grid the search reads inside its compiled loop (no call back into
    Python per expansion): ``grid[i, j, k]`` true (nonzero) marks the voxel
    ``[origin + (i, j, k) res, origin + (i + 1, j + 1, k + 1) res)`` occupied; points outside
    the grid are free (unknown = free). The grid is used as given, not copied, so a map
    that updates it in place is seen by the next search. Also a plain ``occupied`` callable.
    """

    grid: np.ndarray
    origin: np.ndarray
    resolution: float

    def __post_init__(self):
        g = np.asarray(self.grid)
        if g.ndim != 3 or g.dtype not in (np.bool_, np.uint8):
            raise ValueError(f"grid: need a 3-D bool or uint8 array, got {g.dtype} {g.shape}")
        o = np.asarray(self.origin, dtype=float).reshape(-1)
        if o.shape != (3,) or not np.all(np.isfinite(o)):
            raise ValueError(f"origin: need 3 finite numbers, got {self.origin!r}")
        r = self.resolution
        if isinstance(r, bool) or not isinstance(r, (int, float)) or not math.isfinite(r) \
                or r <= 0:
            raise ValueError(f"resolution: must be a positive number of metres, got {r!r}")
        object.__setattr__(self, "grid", g.view(np.uint8) if g.dtype == np.bool_ else g)
        object.__setattr__(self, "origin", o)
        object.__setattr__(self, "resolution", float(r))

    def __call__(self, points) -> np.ndarray:
        pts = np.asarray(points, dtype=float).reshape(-1, 3)
        out = np.empty(len(pts), np.bool_)
        _grid_occupied(self.grid, self.origin, 1.0 / self.resolution, pts, out)
        return out


class KinodynamicAstar:
    """Fast-Planner's kinodynamic A* over a local occupancy map.

    ``occupied(points (N, 3)) -> bool (N,)`` answers for the inflated map (unknown = free);
    a :class:`VoxelOccupancy` is read inside the compiled search loop instead (several
    times faster: no Python call per expansion);
    ``resolution`` is the state-voxel size (Fast-Planner's ``resolution_astar``, equal to
    the map's 0.1 m); ``bounds`` (lower corner, upper corner) confine the search, as the
    map's region does in the original (None: unbounded). One planner runs one search at a
    time (it reuses its arrays); the map callable may change between searches.
    """

    def __init__(self, occupied: OccupancyFn | VoxelOccupancy, resolution: float = 0.1,
                 bounds: tuple[np.ndarray, np.ndarray] | None = None,
                 params: KinoAstarParams | None = None):
        if not callable(occupied):
            raise TypeError("occupied: must be a callable points (N, 3) -> bool (N,)")
        if isinstance(resolution, bool) or not isinstance(resolution, (int, float)) or \
                not math.isfinite(resolution) or resolution <= 0:
            raise ValueError(f"resolution: must be a positive number of metres, "
                             f"got {resolution!r}")
        self.occupied = occupied
        self.resolution = float(resolution)
        self.params = params if params is not None else KinoAstarParams()
        if not isinstance(self.params, KinoAstarParams):
            raise TypeError(f"params: must be a KinoAstarParams, got {type(params).__name__}")
        if bounds is None:
            self._use_bounds = False
            self._lo = np.full(3, -np.inf)
            self._hi = np.full(3, np.inf)
            self._origin = np.zeros(3)
        else:
            lo = np.asarray(bounds[0], dtype=float).reshape(3)
            hi = np.asarray(bounds[1], dtype=float).reshape(3)
            if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi)) and np.all(hi > lo)):
                raise ValueError(f"bounds: need finite corners with max > min, got {bounds!r}")
            self._use_bounds = True
            self._lo, self._hi, self._origin = lo, hi, lo.copy()
        p = self.params
        self._inputs, self._taus = _primitive_set(p.max_acc, p.max_tau)
        self._init_taus = p.init_max_tau * np.arange(1, _INIT_STEPS + 1) / _INIT_STEPS
        self._goal_tol_vox = int(math.ceil(p.goal_tolerance / self.resolution - 1e-9))
        if isinstance(occupied, VoxelOccupancy):
            self._grid, self._grid_origin = occupied.grid, occupied.origin
            grid_inv_res = 1.0 / occupied.resolution
        else:
            self._grid, self._grid_origin = None, np.zeros(3)
            grid_inv_res = 1.0
        self._p = np.array([p.max_vel, p.w_time, p.lambda_heu, p.horizon,
                            1.0 / self.resolution, grid_inv_res])
        self._ws: _Workspace | None = None

    # -- public -----------------------------------------------------------------------

    def search(self, start_pos, start_vel, start_acc, goal_pos, goal_vel=None,
               keep_start_acc: bool = True) -> KinoResult:
        """Search from the start state toward the goal state (goal velocity zero unless
        given). With ``keep_start_acc`` the first expansion keeps ``start_acc``; a search
        that then finds no path is retried with the full input set (when
        ``params.retry_full_inputs``), as Fast-Planner's planner manager does."""
        t0 = time.perf_counter()
        p = self.params
        x0 = np.concatenate([_vec3(start_pos, "start_pos"), _vec3(start_vel, "start_vel")])
        acc0 = _vec3(start_acc, "start_acc")
        gv = np.zeros(3) if goal_vel is None else _vec3(goal_vel, "goal_vel")
        xg = np.concatenate([_vec3(goal_pos, "goal_pos"), gv])
        deadline = None if p.max_time_s is None else t0 + p.max_time_s
        attempts = [self._search_once(x0, acc0, xg, keep_start_acc, deadline)]
        if (attempts[0]["status"] is KinoStatus.NO_PATH and keep_start_acc
                and p.retry_full_inputs and attempts[0]["stop_reason"] != "time_cap"):
            attempts.append(self._search_once(x0, acc0, xg, False, deadline))
        out = attempts[-1]
        return KinoResult(
            status=out["status"], start_state=x0, goal_state=xg, states=out["states"],
            inputs=out["inputs"], durations=out["durations"],
            shot_coeffs=out["shot_coeffs"], shot_duration=out["shot_duration"],
            expansions=sum(a["expansions"] for a in attempts),
            nodes=sum(a["nodes"] for a in attempts),
            search_time_s=time.perf_counter() - t0,
            attempts=len(attempts), kept_start_acc=out["kept_start_acc"],
            stop_reason=out["stop_reason"],
            stats={"per_attempt": [{k: a[k] for k in ("expansions", "nodes", "stop_reason",
                                                      "time_s", "occupancy_queries")}
                                   for a in attempts]},
        )

    def try_shot(self, x0, xg, duration: float) -> np.ndarray | None:
        """The one-shot cubic from ``x0`` to ``xg`` in ``duration`` seconds if 10 points
        along it are free and inside the bounds and (``shot_check_vel``/``shot_check_acc``)
        it keeps within the limits; else None."""
        if not (math.isfinite(duration) and duration > 0.0):
            return None
        coeffs = obvp_coefficients(x0, xg, duration)
        ts = duration * np.arange(1, _SHOT_CHECK_NUM + 1) / _SHOT_CHECK_NUM
        pts, _, _ = _cubic_eval(coeffs, ts)
        if self._use_bounds and (np.any(pts <= self._lo) or np.any(pts >= self._hi)):
            return None
        if np.any(self._occupied(pts)):
            return None
        p = self.params
        vmax = p.max_vel if p.shot_check_vel else np.inf
        amax = p.max_acc if p.shot_check_acc else np.inf
        if not _cubic_within_limits(coeffs, duration, vmax, amax):
            return None
        return coeffs

    # -- internals --------------------------------------------------------------------

    def _occupied(self, pts: np.ndarray) -> np.ndarray:
        occ = np.asarray(self.occupied(pts))
        if occ.shape != (pts.shape[0],):
            raise ValueError(f"occupied() returned shape {occ.shape} for {pts.shape[0]} points")
        return occ.astype(bool, copy=False)

    def _workspace(self) -> _Workspace:
        if self._ws is None:
            p = self.params
            m = max(len(self._inputs) * len(self._taus), len(self._init_taus))
            self._ws = _Workspace(p.max_nodes, p.check_num, m)
        return self._ws

    def _search_once(self, x0, acc0, xg, keep_start_acc, deadline) -> dict:
        t_start = time.perf_counter()
        p = self.params
        ws = self._workspace()
        cnt = ws.cnt
        _reset(cnt, ws.slot, ws.hv, ws.hpos)
        cnt[_C_INIT] = 1 if keep_start_acc else 0
        cnt[_C_MAXEXP] = p.max_expansions
        cnt[_C_MAXNODES] = p.max_nodes
        cnt[_C_CHECK] = p.check_num
        cnt[_C_BOUNDS] = 1 if self._use_bounds else 0
        cnt[_C_TOL] = self._goal_tol_vox
        cnt[_C_GRID] = 0 if self._grid is None else 1
        grid = _NO_GRID if self._grid is None else self._grid
        nodes = ws.nodes()
        _add_root(*nodes, self._p, self._origin, x0, xg)
        goal_vox = np.floor((xg[:3] - self._origin) * self._p[_P_INVRES]).astype(np.int64)
        rest = (self._p, self._origin, self._lo, self._hi, x0[:3].copy(), xg, goal_vox,
                self._inputs, self._taus, acc0.reshape(1, 3).copy(), self._init_taus,
                *ws.scratch(), grid, self._grid_origin)
        args = (*nodes, *rest)
        queries = 0
        shot = None
        shot_t = 0.0
        while True:
            code = _advance(*args)
            if code == _NEED_OCC:
                k = int(cnt[_C_NCAND]) * p.check_num
                ws.occ[:k] = self._occupied(ws.pts[:k])
                queries += 1
            elif code == _GROW:
                ws.grow_hash()
                args = (*ws.nodes(), *rest)
            elif code != _YIELD:
                break
            if deadline is not None and time.perf_counter() > deadline:
                code = 0
                break
        status, node, reason = KinoStatus.NO_PATH, -1, {
            0: "time_cap", _EMPTY: "exhausted", _EXP_CAP: "expansion_cap",
            _NODE_CAP: "node_cap", _TERMINAL: ""}[code]
        if code == _TERMINAL:
            nid = int(cnt[_C_CUR])
            x = ws.x[nid].copy()
            if cnt[_C_NEAR]:
                _, shot_t = _obvp(x, xg, p.w_time, p.max_vel)
                shot = self.try_shot(x, xg, shot_t)
            if shot is not None:
                status, node, reason = KinoStatus.REACHED_GOAL, nid, "goal"
            elif cnt[_C_HORIZON]:
                status, node, reason = KinoStatus.REACHED_HORIZON, nid, "horizon"
            elif ws.par[nid] >= 0:
                status, node, reason = KinoStatus.NEAR_GOAL, nid, "near_goal"
            else:
                reason = "start_shot_failed"
        chain = [0]
        if node >= 0:
            chain = []
            k = node
            while k >= 0:
                chain.append(k)
                k = int(ws.par[k])
            chain.reverse()
        idx = np.array(chain, dtype=np.int64)
        return {"status": status, "states": ws.x[idx].copy(), "inputs": ws.u[idx[1:]].copy(),
                "durations": ws.tau[idx[1:]].copy(), "shot_coeffs": shot,
                "shot_duration": float(shot_t) if shot is not None else 0.0,
                "expansions": int(cnt[_C_EXP]), "nodes": int(cnt[_C_NODES]),
                "stop_reason": reason, "kept_start_acc": bool(keep_start_acc and len(chain) > 1),
                "occupancy_queries": queries, "time_s": time.perf_counter() - t_start}


def _vec3(v, name: str) -> np.ndarray:
    a = np.asarray(v, dtype=float).reshape(-1)
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise ValueError(f"{name}: need 3 finite numbers, got {v!r}")
    return a
