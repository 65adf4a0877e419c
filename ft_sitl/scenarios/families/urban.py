"""Urban (classic): buildings on a street grid, and walls; version 2 runs the start->goal
line along an avenue with street clutter beside and across it. Declared in
:mod:`ft_sitl.scenarios.families`."""

from __future__ import annotations

import math

import numpy as np

from ft_sitl.scenarios.families.common import Family, MeshBuilder, make_scenario, start_altitude
from ft_sitl.scenarios.scenario import Scenario, ScenarioError

#: Urban: probability that the centre line runs along an open boulevard (walls only)
BOULEVARD_PROBABILITY = 0.35


def urban(fam: Family, p: dict, rng: np.random.Generator, index: int, seed: int) -> Scenario:
    """Urban: 60 x 60 m, ceiling 10 m: buildings on a street grid, and walls.

    Blocks fill x in [4, 56], y in [8, 52]: 3 or 5 columns (mirror-symmetric about the
    centre line, so the middle column straddles it) by 3-5 rows, separated by streets
    (4.5-8 m), with a street ring at the edges. A block is a park (empty) with probability
    0.15 -- never in the middle column -- else split into 1-2 x 1-2 lots (1.2 m alleys)
    each holding one box building set back 0.3-0.8 m: 75 % are 12-40 m tall (above the
    ceiling), the rest 3-7 m (the vehicle can cross over them). 4-9 free-standing walls
    (0.3 m thick, 3-10 m long, 2-6 m tall) stand along streets, leaving them passable.
    """
    width, length = p["size_m"]
    alt = start_altitude(p["ceiling_m"])
    zone_x, zone_y = p["block_zone_x_m"], p["block_zone_y_m"]
    corridor = p["line_corridor_m"]
    ncols = int(rng.choice([3, 5]))
    nrows = int(rng.integers(3, 6))
    half = (zone_x[1] - zone_x[0]) / 2.0
    k = (ncols - 1) // 2
    if ncols == 3:
        centre_w = rng.uniform(6.0, 12.0)
        side_streets = rng.uniform(5.0, 8.0, k)
    else:
        centre_w = rng.uniform(5.0, 8.0)
        side_streets = rng.uniform(4.5, 6.5, k)
    weights = rng.uniform(0.7, 1.3, k)
    side_blocks = (half - centre_w / 2 - side_streets.sum()) * weights / weights.sum()
    cx = width / 2.0
    cols = [(cx - centre_w / 2, cx + centre_w / 2)]
    edge = centre_w / 2
    for s, bw in zip(side_streets, side_blocks):
        cols.append((cx + edge + s, cx + edge + s + bw))
        cols.insert(0, (cx - edge - s - bw, cx - edge - s))
        edge += s + bw
    row_streets = rng.uniform(5.0, 7.0, nrows - 1)
    row_w = rng.uniform(0.7, 1.3, nrows)
    row_w = (zone_y[1] - zone_y[0] - row_streets.sum()) * row_w / row_w.sum()
    rows, y = [], zone_y[0]
    for j in range(nrows):
        rows.append((y, y + row_w[j]))
        y += row_w[j] + (row_streets[j] if j < nrows - 1 else 0.0)
    mid = ncols // 2
    alley = p["alley_m"]
    # the middle column as an open boulevard: no buildings, a wall beside the line instead
    boulevard = bool(rng.random() < p["boulevard_probability"])
    b = MeshBuilder()
    buildings, walls = [], []
    for i, (x0, x1) in enumerate(cols):
        if boulevard and i == mid:
            continue
        for y0, y1 in rows:
            park = rng.random() < p["park_probability"]
            if park and i != mid:
                continue
            nx = 1 if (i == mid or x1 - x0 < 8.0) else int(rng.integers(1, 3))
            ny = 1 if y1 - y0 < 8.0 else int(rng.integers(1, 3))
            xs = _split(rng, x0, x1, nx, alley)
            ys = _split(rng, y0, y1, ny, alley)
            for lot_x in xs:
                for lot_y in ys:
                    _building(rng, p, b, buildings, lot_x, lot_y)
    streets_ns = [(cols[i][1], cols[i + 1][0]) for i in range(ncols - 1)]
    streets_ew = [(rows[j][1], rows[j + 1][0]) for j in range(nrows - 1)]
    for _ in range(int(rng.integers(4, 10))):
        thick = 0.3
        wlen = rng.uniform(*p["wall_length_m"])
        h = rng.uniform(*p["wall_height_m"])
        if rng.random() < 0.5:  # along a north-south street
            a, c = streets_ns[int(rng.integers(len(streets_ns)))]
            xw = rng.uniform(a + 0.5, c - 0.5 - thick)
            yw = rng.uniform(zone_y[0], zone_y[1] - wlen)
            lo, hi = (xw, yw, 0.0), (xw + thick, yw + wlen, h)
        else:  # along an east-west street
            a, c = streets_ew[int(rng.integers(len(streets_ew)))]
            yw = rng.uniform(a + 0.5, c - 0.5 - thick)
            xw = rng.uniform(zone_x[0], zone_x[1] - wlen)
            lo, hi = (xw, yw, 0.0), (xw + wlen, yw + thick, h)
        b.box(lo, hi, "wall")
        walls.append([*lo, *hi])
    if boulevard:  # a wall along the line, its near face 0..line_corridor_m beside it
        thick, wlen, h = 0.3, rng.uniform(*p["wall_length_m"]), rng.uniform(3.0, 6.0)
        offset = rng.uniform(0.0, corridor)
        yw = rng.uniform(zone_y[0], zone_y[1] - wlen)
        x_near = cx + offset if rng.random() < 0.5 else cx - offset - thick
        lo, hi = (x_near, yw, 0.0), (x_near + thick, yw + wlen, h)
        b.box(lo, hi, "wall")
        walls.append([*lo, *hi])
    return make_scenario(
        fam, index, seed, b, p, altitude=alt, obstacle_count=len(buildings) + len(walls),
        corridor=corridor, derived={"start_altitude_m": alt},
        layout={"columns_x_m": cols, "rows_y_m": rows, "buildings_lo_hi": buildings,
                "walls_lo_hi": walls, "boulevard": boulevard},
    )


#: Urban (version 2): obstacles in the avenue keep their footprints this far apart (m)
URBAN_ITEM_GAP_M = 2.5
#: Urban (version 2): obstacles across the line stand at least this far apart along it (m)
URBAN_BARRIER_SPACING_M = 7.0
#: Urban (version 2): an obstacle across the line leaves at least this much of the avenue
#: open on each side (m; min_passage_m on one of them)
URBAN_SIDE_GAP_M = 2.5
#: Urban (version 2): the avenue's obstacles stand this far inside the blocks' y range at
#: the start's and the goal's end (m)
URBAN_AVENUE_MARGIN_M = (5.0, 1.0)
#: Urban (version 2): a block (or a row of blocks) is at least this wide / long (m)
URBAN_MIN_BLOCK_M = 4.0


def urban_barrier_count(index: int) -> int:
    """Urban (version 2): walls across the start->goal line at flight altitude in
    configuration ``index``: 0, 0, 0, 1, 1, 2, 2, 3, 3, 4 for index 1..10."""
    return max(0, (index - 2) // 2)


def urban_v2(fam: Family, p: dict, rng: np.random.Generator, index: int,
             seed: int) -> Scenario:
    """Urban (version 2): 60 x 60 m, ceiling 10 m: streets and blocks; the start->goal line
    runs along an avenue, with trucks and walls beside and across it.

    Why: the paper's Urban is "structured but cluttered geometry with vertical obstacles
    resembling buildings and walls", an open field where "all algorithms perform well"
    and the straight-flight baseline succeeds in about 10-20 % of the trials. Version 1
    ran the line through a column of buildings in most configurations: every algorithm,
    the baseline included, hit the same first building. Here no building stands on the
    line; what stands on it is street clutter a planner passes at flight altitude.

    The street grid. The avenue (its building lines 6-8 m from the line, drawn per side)
    runs the whole length. Blocks fill x in [4, 56], y in [8, 52], inside a ring street:
    on each side of the avenue two block columns split by a north-south side street, and
    3-4 rows split by 2-3 east-west cross streets (streets 5-7 m wide). A block is split
    into 1-2 x 1-2 lots (1.2 m alleys; a side of 8 m or more may split), each holding one
    box building set back 0.3-0.8 m: 70 % are 12-40 m tall (above the ceiling), the rest
    3-8 m (the vehicle may cross over them). A block not facing the avenue is a park
    (empty) with probability 0.15, so buildings line the avenue.

    The avenue's obstacles stand in y in [13, 51] (10 m of clear avenue after the start,
    6 m before the goal), their footprints >= 2.5 m apart, two beside the line never
    abreast (that would be a gate, Narrow-Gap's test):

    * beside the line, parallel to it on a random side: 1-3 trucks (2.5 m wide, 4-7 m
      long, 3-4 m tall; 60 %) or median walls (0.5 m thick, 3-6 m long, 3-5 m tall). The
      first stands with its near face a uniform 0-0.6 m (``line_corridor_m``) from the
      line -- the open-family rule of the package docstring: the baseline, which flies
      the line, hits it unless its body is narrower than the gap -- the others 1-2.5 m off.
    * across the line at flight altitude: ``barrier_count`` = 0, 0, 0, 1, 1, 2, 2, 3, 3, 4
      (index 1..10) free-standing trucks (2.5 m deep, 4.5-6.5 m long, 3-4 m tall) or
      walls (0.5 m thick, 3-6 m long), half each, >= 7 m apart along the avenue. The line
      crosses each >= 0.6 m from its ends (no platform flies past it), and each leaves
      >= 2.5 m of the avenue open on both sides, >= 4 m on one. A wall's height is uniform
      in [3, 3 + 5 (index - 1) / 9] m: up to 8 m, under the 10 m ceiling. Difficulty --
      how many obstacles cross the line, and how tall -- rises with the index.
    * across the avenue, out of the way at flight altitude: a low wall over its whole
      width (0.4 m thick, 0.5-1 m tall), and with probability 0.5 an overhead passage
      between its buildings (2.5-4 m deep, 1.5-2.5 m thick, underside 4.5-6.5 m) over a
      row of blocks.

    So in configurations 1-3 only the truck or wall beside the line stands in the
    baseline's way (a platform narrower than the gap slips past), and from 4 on an
    obstacle across the line stops it: ~14 % baseline success over the catalog and the
    ten configurations (seeds 0-7, exact body checks along the line), as in the paper.
    Each obstacle across leaves passages on both sides at flight altitude, so no
    configuration is blocked for every algorithm at one obstacle (tests: a level path
    below 3 m exists for the largest body); side streets give further detours. 3-6
    free-standing walls (0.3 m thick, 3-8 m long, 2-6 m tall) stand along the side and
    cross streets, outside the avenue.
    """
    width, length = p["size_m"]
    alt = start_altitude(p["ceiling_m"])
    (zx0, zx1), (zy0, zy1) = p["block_zone_x_m"], p["block_zone_y_m"]
    corridor = p["line_corridor_m"]
    cx = width / 2.0
    half = rng.uniform(*p["avenue_half_width_m"], 2)  # west, east
    ave = (cx - half[0], cx + half[1])
    if not zx0 + URBAN_MIN_BLOCK_M <= ave[0] < ave[1] <= zx1 - URBAN_MIN_BLOCK_M:
        raise ScenarioError(f"urban #{index}: the avenue {ave[0]:.2f}..{ave[1]:.2f} m leaves "
                            f"no blocks in block_zone_x_m [{zx0:g}, {zx1:g}]")
    # block columns: on each side of the avenue two, split by a side street (one if narrow)
    cols: list[tuple[float, float]] = []
    facing: list[bool] = []  # the column lines the avenue
    streets_ns: list[tuple[float, float]] = []
    for a, c, west_side in ((zx0, ave[0], True), (ave[1], zx1, False)):
        street = rng.uniform(*p["street_width_m"])
        blocks = c - a - street
        if blocks >= 2 * URBAN_MIN_BLOCK_M:
            cut = a + blocks * rng.uniform(0.4, 0.6)
            parts = [(a, cut), (cut + street, c)]
            streets_ns.append((cut, cut + street))
        else:
            parts = [(a, c)]
        cols += parts
        facing += [k == (len(parts) - 1 if west_side else 0) for k in range(len(parts))]
    # rows of blocks between the cross streets
    lo_n, hi_n = p["cross_streets"]
    n_cross = int(rng.integers(lo_n, hi_n + 1))
    cross_w = rng.uniform(*p["street_width_m"], n_cross)
    spare = zy1 - zy0 - cross_w.sum()
    if spare < (n_cross + 1) * URBAN_MIN_BLOCK_M:
        raise ScenarioError(f"urban #{index}: {n_cross} cross streets leave no rows of blocks "
                            f"in block_zone_y_m [{zy0:g}, {zy1:g}]")
    weights = rng.uniform(0.7, 1.3, n_cross + 1)
    row_len = spare * weights / weights.sum()
    rows, y = [], zy0
    for j in range(n_cross + 1):
        rows.append((y, y + row_len[j]))
        y += row_len[j] + (cross_w[j] if j < n_cross else 0.0)
    streets_ew = [(rows[j][1], rows[j + 1][0]) for j in range(n_cross)]

    b = MeshBuilder()
    buildings = []
    alley = p["alley_m"]
    for (x0, x1), on_avenue in zip(cols, facing):
        for y0, y1 in rows:
            if not on_avenue and rng.random() < p["park_probability"]:
                continue
            nx = 1 if x1 - x0 < 8.0 else int(rng.integers(1, 3))
            ny = 1 if y1 - y0 < 8.0 else int(rng.integers(1, 3))
            for lot_x in _split(rng, x0, x1, nx, alley):
                for lot_y in _split(rng, y0, y1, ny, alley):
                    _building(rng, p, b, buildings, lot_x, lot_y)

    # the avenue's obstacles: kind (the piece's name), role, box
    items: list[dict] = []
    y_lo, y_hi = zy0 + URBAN_AVENUE_MARGIN_M[0], zy1 - URBAN_AVENUE_MARGIN_M[1]

    def fits(lo, hi, role: str) -> bool:
        """Footprints URBAN_ITEM_GAP_M apart; two obstacles beside the line not abreast
        (a gate across the line would be a narrow gap, another family's test)."""
        for it in items:
            dx = max(it["lo"][0] - hi[0], lo[0] - it["hi"][0], 0.0)
            dy = max(it["lo"][1] - hi[1], lo[1] - it["hi"][1], 0.0)
            if math.hypot(dx, dy) < URBAN_ITEM_GAP_M or (
                    role == it["role"] == "beside" and dy < URBAN_ITEM_GAP_M):
                return False
        return True

    def place(draw, role: str, tries: int = 500) -> bool:
        """Add the first of ``tries`` draws (kind, lo, hi) whose footprint fits."""
        for _ in range(tries):
            kind, lo, hi = draw()
            if fits(lo, hi, role):
                items.append({"kind": kind, "role": role, "lo": list(lo), "hi": list(hi)})
                return True
        return False

    def beside(offset):
        """A truck or a median wall parallel to the line, its near face ``offset`` from it."""
        def draw():
            truck = rng.random() < 0.6
            east = rng.random() < 0.5
            off = rng.uniform(*offset)
            w, ln, h = ((2.5, rng.uniform(4.0, 7.0), rng.uniform(3.0, 4.0)) if truck
                        else (0.5, rng.uniform(3.0, 6.0), rng.uniform(3.0, 5.0)))
            y0 = rng.uniform(y_lo, y_hi - ln)
            xn = cx + off if east else cx - off - w
            return ("truck" if truck else "wall"), (xn, y0, 0.0), (xn + w, y0 + ln, h)
        return draw

    def across(yc):
        """A truck or a wall across the line at ``yc``: the line crosses it >= 0.6 m from
        its ends, both passages beside it >= URBAN_SIDE_GAP_M, one >= min_passage_m."""
        for _ in range(1000):
            truck = bool(rng.random() < 0.5)
            ln, depth, h = ((rng.uniform(4.5, 6.5), 2.5, rng.uniform(3.0, 4.0)) if truck else
                            (rng.uniform(3.0, 6.0), 0.5, rng.uniform(h_lo, h_top)))
            c_lo = max(-(ln / 2 - 0.6), ln / 2 + URBAN_SIDE_GAP_M - half[0])
            c_hi = min(ln / 2 - 0.6, half[1] - ln / 2 - URBAN_SIDE_GAP_M)
            if c_lo > c_hi:
                continue
            c = cx + rng.uniform(c_lo, c_hi)
            x0, x1 = c - ln / 2, c + ln / 2
            if max(x0 - ave[0], ave[1] - x1) >= p["min_passage_m"]:
                return ("truck" if truck else "wall"), (x0, yc - depth / 2, 0.0), \
                    (x1, yc + depth / 2, h)
        raise ScenarioError(f"urban #{index}: the avenue is too narrow for an obstacle across "
                            f"the line leaving min_passage_m = {p['min_passage_m']:g} m "
                            "beside it")

    def low_wall():
        y0 = rng.uniform(y_lo, y_hi - 0.4)
        h = rng.uniform(*p["low_wall_height_m"])
        return "low wall", (ave[0] - 1.0, y0, 0.0), (ave[1] + 1.0, y0 + 0.4, h)

    # the obstacle beside the line (the open-family rule) and those across it, drawn together
    n_bar = urban_barrier_count(index)
    h_lo, h_hi = p["barrier_height_m"]
    h_top = h_lo + (h_hi - h_lo) * (index - 1) / 9.0
    first = beside((0.0, corridor))
    for _ in range(5000):
        items.clear()
        kind, lo, hi = first()
        items.append({"kind": kind, "role": "beside", "lo": list(lo), "hi": list(hi)})
        ys = np.sort(rng.uniform(y_lo + 1.5, y_hi - 1.5, n_bar))
        if np.any(np.diff(ys) < URBAN_BARRIER_SPACING_M):  # along the avenue, spaced
            continue
        drawn = [across(yc) for yc in ys]
        if all(fits(lo, hi, "across") for _, lo, hi in drawn):
            items.extend({"kind": k, "role": "across", "lo": list(lo), "hi": list(hi)}
                         for k, lo, hi in drawn)
            break
    else:
        raise ScenarioError(f"urban #{index}: no room for {n_bar} obstacles across the line "
                            f"{URBAN_BARRIER_SPACING_M:g} m apart and one beside it in y "
                            f"[{y_lo:g}, {y_hi:g}]")
    if not place(low_wall, "under"):
        raise ScenarioError(f"urban #{index}: no room for the low wall across the avenue in "
                            f"y [{y_lo:g}, {y_hi:g}]")
    spans = [(max(r0, y_lo), min(r1, y_hi)) for r0, r1 in rows]
    spans = [(r0, r1) for r0, r1 in spans if r1 - r0 >= 6.0]  # the deepest bridge fits

    def bridge():  # over a row of blocks, its ends 1 m into the buildings
        depth, thick = rng.uniform(2.5, 4.0), rng.uniform(1.5, 2.5)
        under = rng.uniform(*p["bridge_underside_m"])
        r0, r1 = spans[int(rng.integers(len(spans)))]
        y0 = rng.uniform(r0 + 1.0, r1 - 1.0 - depth)
        return "bridge", (ave[0] - 1.0, y0, under), (ave[1] + 1.0, y0 + depth, under + thick)

    if rng.random() < p["bridge_probability"] and spans:
        place(bridge, "over")
    for _ in range(int(rng.integers(1, 3))):
        place(beside((1.0, 2.5)), "beside")
    for it in items:
        b.box(it["lo"], it["hi"], it["kind"])

    # free-standing walls along the side and cross streets, outside the avenue
    walls = []
    for _ in range(int(rng.integers(3, 7))):
        wlen, h = rng.uniform(*p["wall_length_m"]), rng.uniform(*p["wall_height_m"])
        if streets_ns and (not streets_ew or rng.random() < 0.5):
            a, c = streets_ns[int(rng.integers(len(streets_ns)))]
            xw, yw = rng.uniform(a + 0.5, c - 0.8), rng.uniform(zy0, zy1 - wlen)
            lo, hi = (xw, yw, 0.0), (xw + 0.3, yw + wlen, h)
        elif streets_ew:
            a, c = streets_ew[int(rng.integers(len(streets_ew)))]
            x0, x1 = (zx0, ave[0] - 1.0) if rng.random() < 0.5 else (ave[1] + 1.0, zx1)
            wlen = min(wlen, x1 - x0)
            xw, yw = rng.uniform(x0, x1 - wlen), rng.uniform(a + 0.5, c - 0.8)
            lo, hi = (xw, yw, 0.0), (xw + wlen, yw + 0.3, h)
        else:
            break
        b.box(lo, hi, "wall")
        walls.append([*lo, *hi])
    return make_scenario(
        fam, index, seed, b, p, altitude=alt,
        obstacle_count=len(buildings) + len(items) + len(walls), corridor=corridor,
        derived={"barrier_count": n_bar, "start_altitude_m": alt},
        layout={"avenue_x_m": ave, "columns_x_m": cols, "rows_y_m": rows,
                "side_streets_x_m": streets_ns, "cross_streets_y_m": streets_ew,
                "buildings_lo_hi": buildings, "avenue_obstacles": items,
                "walls_lo_hi": walls},
    )


def _building(rng, p: dict, b: MeshBuilder, buildings: list, lot_x, lot_y) -> None:
    """One box building on the lot ``lot_x`` x ``lot_y`` ((lo, hi) each): set back
    0.3-0.8 m (at most a fifth of the lot's shorter side), tall (``tall_height_m``) with
    ``tall_probability``, else low (``low_height_m``); added to ``b`` and, as lo + hi, to
    ``buildings``."""
    (lx0, lx1), (ly0, ly1) = lot_x, lot_y
    s = min(rng.uniform(0.3, 0.8), 0.2 * min(lx1 - lx0, ly1 - ly0))
    tall = rng.random() < p["tall_probability"]
    h = rng.uniform(*p["tall_height_m" if tall else "low_height_m"])
    lo, hi = (lx0 + s, ly0 + s, 0.0), (lx1 - s, ly1 - s, h)
    b.box(lo, hi, "building")
    buildings.append([*lo, *hi])


def _split(rng, a, b, n, alley):
    if n == 1:
        return [(a, b)]
    cut = a + (b - a) * rng.uniform(0.35, 0.65)
    return [(a, cut - alley / 2), (cut + alley / 2, b)]
