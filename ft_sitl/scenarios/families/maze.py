"""Maze (theoretical): version 1 a perfect maze (recursive backtracker), version 2 recursive
division with loops and bounded routes. Declared in :mod:`ft_sitl.scenarios.families`."""

from __future__ import annotations

import heapq
import math

import numpy as np

from ft_sitl.scenarios.families.common import Family, MeshBuilder, make_scenario, start_altitude
from ft_sitl.scenarios.scenario import INDEX_RANGE, Scenario, ScenarioError


def maze(fam: Family, p: dict, rng: np.random.Generator, index: int, seed: int) -> Scenario:
    """Maze: 25 x 40 m, ceiling 2 m; a perfect maze (one path between any two cells).

    11 x 17 cells (2.27 x 2.35 m; corridors >= 2.07 m between 0.2 m walls, 2.5 m tall),
    carved by an iterative recursive backtracker from the start cell (the middle of the
    first row); the goal is the middle of the last row. A layout whose middle column is a
    straight corridor (start->goal line clear) is redrawn. Dead ends are counted.
    """
    width, length = p["size_m"]
    alt = start_altitude(p["ceiling_m"])
    (nx, ny), thick, height = p["cells"], p["wall_thickness_m"], p["wall_height_m"]
    cw, ch = width / nx, length / ny
    mid = nx // 2
    for _ in range(100):
        east, north = _carve(rng, nx, ny, (mid, 0))
        if not north[mid, :-1].all():  # a wall crosses the middle column
            break
    else:  # pragma: no cover - probability ~0
        raise RuntimeError(f"maze #{index}: every layout left the line clear")
    b = MeshBuilder()
    runs = _maze_walls(b, east, north, cw, ch, thick, height)
    degree = _maze_degree(east, north)
    dead_ends = int((degree == 1).sum())
    return make_scenario(
        fam, index, seed, b, p, altitude=alt, obstacle_count=runs,
        start_xy=((mid + 0.5) * cw, 0.5 * ch), goal_xy=((mid + 0.5) * cw, (ny - 0.5) * ch),
        derived={"cell_m": [cw, ch], "corridor_width_m": min(cw, ch) - thick,
                 "start_altitude_m": alt},
        layout={"dead_ends": dead_ends,
                "east_passages": east[:-1, :].astype(int).tolist(),
                "north_passages": north[:, :-1].astype(int).tolist()},
    )


#: draws of a layout before giving up on the bounds (the default parameters need ~1-60)
MAZE_ATTEMPTS = 20_000


def maze_v2(fam: Family, p: dict, rng: np.random.Generator, index: int,
            seed: int) -> Scenario:
    """Maze, version 2: 25 x 40 m, ceiling 2 m; dead ends and loops, a route that a 4 m/s
    vehicle flies well within 90 s, and more exploration the higher the index.

    Why: version 1's perfect 11 x 17 mazes had shortest routes of 98-259 m with 23-72
    turns and 3-14 legs heading south (away from the goal), and the start cell was closed
    towards the goal in 8 of 10 configurations: hopeless for a goal-directed local planner
    in 90 s (0 % for every algorithm). The paper's planners succeed in ~15 % of its maze trials,
    NavRL in < 10 %, the baseline never (Sec. IV-B).

    How: 7 x 10 cells (3.57 x 4 m; corridors >= 3.37 m between 0.2 m walls, 2.5 m tall,
    above the 2 m ceiling) are drawn by recursive division, the maze of the original
    planners' map generator (mockamap): each chamber is cut across its longer side (in
    cells; a tie is a coin toss) by a wall with one door, down to corridors one cell wide
    (a perfect maze). Then 6 interior walls chosen at random are removed (loops: more than
    one way round, as in a real building), and the start cell (the middle of the first
    row) is opened to the north, towards the goal (the middle of the last row). A layout
    is kept only if

    * a wall crosses the straight start->goal line;
    * its shortest route (through cell centres; the fewest turns among the shortest) is
      at most 1.8 x the straight line (64.8 m), turns at most 12 times, and flying it at
      4 m/s with 3 m/s^2, stopping at every turn, takes at most 45 s: half the 90 s
      budget, so a vehicle that knew the way would have time to spare;
    * its difficulty is this configuration's: a goal-greedy explorer (depth first; at
      each cell it enters the open neighbour nearest to the goal, backs out of dead ends,
      and is unlucky at ties) wastes no step in configuration 1 and 34-36 in configuration
      10, the bands rising linearly in between (2-4, 6-8, ...). What it wastes are dead
      ends that face the goal, where a local planner has to turn back and replan.

    Otherwise the layout is redrawn from the same stream (``draws`` in the layout). The
    route, its length, turns, legs heading away from the goal and stop-and-go time, the
    explorer's waste, the dead ends and the loops are recorded in the provenance.
    """
    width, length = p["size_m"]
    alt = start_altitude(p["ceiling_m"])
    (nx, ny), thick, height = p["cells"], p["wall_thickness_m"], p["wall_height_m"]
    cw, ch = width / nx, length / ny
    mid = nx // 2
    start, goal = (mid, 0), (mid, ny - 1)
    straight = (ny - 1) * ch
    band = _detour_band(p["detour_cells"], index)
    draws = 0
    while True:
        draws += 1
        if draws > MAZE_ATTEMPTS:
            raise ScenarioError(f"maze #{index}: no layout within the route bounds and the "
                                f"detour band {band} in {MAZE_ATTEMPTS} draws; loosen "
                                "route_factor_max, route_turns_max, route_time_max_s or "
                                "detour_cells")
        east, north = _divide(rng, nx, ny)
        _open_walls(rng, east, north, p["extra_passages"])
        north[mid, 0] = True  # the start cell opens towards the goal
        if north[mid, :-1].all():  # the middle column is a straight corridor
            continue
        route = _maze_route(east, north, start, goal, cw, ch)
        legs = _legs(route, cw, ch)
        route_m = sum(leg for leg, _ in legs)
        route_s = sum(_stop_and_go_s(leg, p["route_speed_m_s"], p["route_acc_m_s2"])
                      for leg, _ in legs)
        if route_m > p["route_factor_max"] * straight + 1e-9 or \
                len(legs) - 1 > p["route_turns_max"] or route_s > p["route_time_max_s"]:
            continue
        detour = _greedy_detour(east, north, start, goal, cw, ch)
        if band[0] <= detour <= band[1]:
            break
    b = MeshBuilder()
    runs = _maze_walls(b, east, north, cw, ch, thick, height)
    degree = _maze_degree(east, north)
    passages = int(east.sum() + north.sum())
    return make_scenario(
        fam, index, seed, b, p, altitude=alt, obstacle_count=runs,
        start_xy=((mid + 0.5) * cw, 0.5 * ch), goal_xy=((mid + 0.5) * cw, (ny - 0.5) * ch),
        derived={"cell_m": [cw, ch], "corridor_width_m": min(cw, ch) - thick,
                 "detour_band_cells": list(band), "start_altitude_m": alt},
        layout={"dead_ends": int((degree == 1).sum()),
                "loops": passages - (nx * ny - 1),
                "route_cells": [list(c) for c in route],
                "route_length_m": route_m,
                "straight_m": straight,
                "route_turns": len(legs) - 1,
                "route_legs_away": sum(1 for _, d in legs if d == (0, -1)),
                "route_stop_and_go_s": route_s,
                "greedy_detour_cells": detour,
                "draws": draws,
                "east_passages": east[:-1, :].astype(int).tolist(),
                "north_passages": north[:, :-1].astype(int).tolist()},
    )


def _detour_band(lo_hi, index: int) -> tuple[int, int]:
    """Configuration ``index``'s band of a greedy explorer's wasted steps: the target
    rises linearly from lo (index 1) to hi (index 10), rounded to an even number (a
    dead-end cell costs two steps, in and out), and the band is [target - 2, target]."""
    lo, hi = lo_hi
    first, last = INDEX_RANGE
    target = int(2 * round((lo + (hi - lo) * (index - first) / (last - first)) / 2))
    if index == first:
        return target, target
    return max(int(lo), target - 2), target


def _divide(rng, nx, ny):
    """Perfect maze by recursive division (east / north as in :func:`_carve`): a chamber
    two or more cells wide and long is cut across its longer side (in cells; a tie is a
    coin toss) at a random line, with one door at a random cell of the cut."""
    east = np.zeros((nx, ny), dtype=bool)
    north = np.zeros((nx, ny), dtype=bool)
    east[:-1, :] = True
    north[:, :-1] = True
    chambers = [(0, 0, nx, ny)]
    while chambers:
        x0, y0, x1, y1 = chambers.pop()
        w, h = x1 - x0, y1 - y0
        if w < 2 or h < 2:
            continue
        if h > w or (h == w and rng.random() < 0.5):  # a wall along x above row y
            y = int(rng.integers(y0, y1 - 1))
            door = int(rng.integers(x0, x1))
            north[x0:x1, y] = False
            north[door, y] = True
            chambers += [(x0, y0, x1, y + 1), (x0, y + 1, x1, y1)]
        else:  # a wall along y east of column x
            x = int(rng.integers(x0, x1 - 1))
            door = int(rng.integers(y0, y1))
            east[x, y0:y1] = False
            east[x, door] = True
            chambers += [(x0, y0, x + 1, y1), (x + 1, y0, x1, y1)]
    return east, north


def _open_walls(rng, east, north, count: int) -> None:
    """Remove ``count`` interior walls chosen at random (each closes a loop)."""
    nx, ny = east.shape
    walls = [(east, i, j) for i in range(nx - 1) for j in range(ny) if not east[i, j]] + \
            [(north, i, j) for i in range(nx) for j in range(ny - 1) if not north[i, j]]
    if count > len(walls):
        raise ScenarioError(f"maze: extra_passages {count} but only {len(walls)} interior "
                            "walls to remove")
    for k in rng.choice(len(walls), count, replace=False):
        grid, i, j = walls[int(k)]
        grid[i, j] = True


def _maze_neighbours(east, north, cell):
    """The cells that ``cell`` opens into (east, west, north, south)."""
    i, j = cell
    nx, ny = east.shape
    if i + 1 < nx and east[i, j]:
        yield (i + 1, j)
    if i > 0 and east[i - 1, j]:
        yield (i - 1, j)
    if j + 1 < ny and north[i, j]:
        yield (i, j + 1)
    if j > 0 and north[i, j - 1]:
        yield (i, j - 1)


def _maze_route(east, north, start, goal, cw: float, ch: float) -> list[tuple[int, int]]:
    """The shortest route in metres between cell centres (fewest turns among equals;
    Dijkstra over cell and heading)."""
    best = {}
    queue = [(0.0, 0, start, (0, 0), (start,))]
    while queue:
        metres, turns, cell, heading, path = heapq.heappop(queue)
        if cell == goal:
            return list(path)
        if best.get((cell, heading), (math.inf, 0)) <= (metres, turns):
            continue
        best[(cell, heading)] = (metres, turns)
        for nb in _maze_neighbours(east, north, cell):
            step = (nb[0] - cell[0], nb[1] - cell[1])
            turn = int(heading != (0, 0) and step != heading)
            heapq.heappush(queue, (metres + (cw if step[0] else ch), turns + turn, nb, step,
                                   path + (nb,)))
    raise RuntimeError("maze: the goal cell is not connected to the start cell")


def _legs(route, cw: float, ch: float) -> list[tuple[float, tuple[int, int]]]:
    """The route's straight legs: (length in metres, direction (di, dj))."""
    legs: list[list] = []
    for a, b in zip(route[:-1], route[1:]):
        step = (b[0] - a[0], b[1] - a[1])
        if legs and legs[-1][1] == step:
            legs[-1][0] += cw if step[0] else ch
        else:
            legs.append([cw if step[0] else ch, step])
    return [(float(m), d) for m, d in legs]


def _stop_and_go_s(leg_m: float, speed: float, acc: float) -> float:
    """Time to fly ``leg_m`` from rest to rest at most at ``speed`` with ``acc``."""
    if leg_m >= speed * speed / acc:
        return leg_m / speed + speed / acc
    return 2.0 * math.sqrt(leg_m / acc)


def _greedy_detour(east, north, start, goal, cw: float, ch: float) -> int:
    """Steps a depth-first explorer wastes before it reaches the goal (its walk minus its
    final path): at each cell it enters the unvisited open neighbour nearest to the goal
    and backs out of a cell with none left. An unlucky one: of two neighbours equally near
    (either side of the straight line) it may take either, and the worse of the two tie
    orders (west first, east first) counts."""
    def dist(c):
        return math.hypot((c[0] - goal[0]) * cw, (c[1] - goal[1]) * ch)

    def walk(side: int) -> int:
        seen, stack, steps = {start}, [start], 0
        while stack[-1] != goal:
            options = [n for n in _maze_neighbours(east, north, stack[-1]) if n not in seen]
            if options:
                nxt = min(options, key=lambda c: (dist(c), side * c[0], c[1]))
                seen.add(nxt)
                stack.append(nxt)
            else:
                stack.pop()
            steps += 1
        return steps - (len(stack) - 1)

    return max(walk(1), walk(-1))


def _maze_degree(east, north) -> np.ndarray:
    """How many passages each cell has (1: a dead end)."""
    degree = np.zeros(east.shape, dtype=int)
    degree[:-1, :] += east[:-1, :]
    degree[1:, :] += east[:-1, :]
    degree[:, :-1] += north[:, :-1]
    degree[:, 1:] += north[:, :-1]
    return degree


def _maze_walls(b: MeshBuilder, east, north, cw: float, ch: float, thick: float,
                height: float) -> int:
    """Box walls on the cell grid's lines wherever there is no passage (collinear wall
    segments merged into one box; the outer walls closed); returns the number of boxes."""
    nx, ny = east.shape
    t2 = thick / 2
    runs = 0
    for i in range(nx + 1):  # vertical lines x = i * cw
        closed = np.ones(ny, dtype=bool) if i in (0, nx) else ~east[i - 1, :]
        for j0, j1 in _runs(closed):
            b.box((i * cw - t2, j0 * ch - t2, 0.0), (i * cw + t2, j1 * ch + t2, height),
                  "wall")
            runs += 1
    for j in range(ny + 1):  # horizontal lines y = j * ch
        closed = np.ones(nx, dtype=bool) if j in (0, ny) else ~north[:, j - 1]
        for i0, i1 in _runs(closed):
            b.box((i0 * cw - t2, j * ch - t2, 0.0), (i1 * cw + t2, j * ch + t2, height),
                  "wall")
            runs += 1
    return runs


def _carve(rng, nx, ny, start):
    """Perfect maze: east[i, j] / north[i, j] say cell (i, j) opens east / north."""
    east = np.zeros((nx, ny), dtype=bool)
    north = np.zeros((nx, ny), dtype=bool)
    seen = np.zeros((nx, ny), dtype=bool)
    seen[start] = True
    stack = [start]
    while stack:
        i, j = stack[-1]
        options = [(di, dj) for di, dj in ((1, 0), (-1, 0), (0, 1), (0, -1))
                   if 0 <= i + di < nx and 0 <= j + dj < ny and not seen[i + di, j + dj]]
        if not options:
            stack.pop()
            continue
        di, dj = options[int(rng.integers(len(options)))]
        if di:
            east[min(i, i + di), j] = True
        else:
            north[i, min(j, j + dj)] = True
        seen[i + di, j + dj] = True
        stack.append((i + di, j + dj))
    return east, north


def _runs(mask):
    """(start, end) of each run of True in a 1-D mask, end exclusive."""
    out, start = [], None
    for k, v in enumerate(list(mask) + [False]):
        if v and start is None:
            start = k
        elif not v and start is not None:
            out.append((start, k))
            start = None
    return out
