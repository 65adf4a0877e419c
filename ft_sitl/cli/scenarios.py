"""``ft-sitl scenarios``: list, build, export and draw the scenario families."""

from __future__ import annotations

import inspect
import json
import math
import time
from pathlib import Path

from tqdm import tqdm

from ft_sitl.cli.common import CliError, check_out_dir, fmt_point, print_schema_rows
from ft_sitl.missions.spec import flight_budget
from ft_sitl.physics.catalog import largest_platform
from ft_sitl.scenarios.difficulty import (
    TURN_DEG,
    Difficulty,
    cached_difficulty,
    default_cache_dir,
    num,
    summarise,
)
from ft_sitl.scenarios.families import (
    CATEGORY,
    FAMILIES,
    PAPER_NAMES,
    build_scenario,
    describe_family,
    resolve_family,
)
from ft_sitl.scenarios.io import (
    EXPORT_FORMATS,
    export_scenario,
    load_scenario,
    write_scenario_spec,
)
from ft_sitl.scenarios.render import DPI_RANGE, load_trajectory, render_scenario
from ft_sitl.scenarios.scenario import INDEX_RANGE, ScenarioError

SCENARIO_DESCRIPTIONS = {
    "forest": "random upright tree trunks (paper density 1/49 per m^2)",
    "urban": "a street grid; trucks and walls beside and across the avenue route",
    "random_angle_cylinder": "random cylinders tilted 0-180 deg (paper density 1/36 per m^2)",
    "narrow_gap": "walls across the route, one 0.85-0.90 m gap each, on the line or 1-2 m "
                  "beside it; index = walls",
    "sudden_drop": "overhanging blocks from 1.5 m up, start at 2.5 m; index = blocks",
    "maze": "a 7 x 10-cell maze with dead ends and loops; the start opens towards the goal",
    "perlin": "~2,000 blobs of 0.1 m cells where 3-D Perlin noise (1 cycle/m, mockamap's "
              "reading) is in its top 3 %",
}
"""One line per family for ``scenarios list`` (what it is made of and what index does)."""


def _scenario_from_args(args):
    """The scenario the FAMILY / --file, --index, --seed options name."""
    if args.file is not None:
        if args.family is not None:
            raise CliError(f"give a FAMILY or --file, not both (got {args.family!r} and "
                           f"--file {args.file})")
        if args.index is not None or args.seed is not None:
            raise CliError("--index and --seed do not apply to --file (the spec sets them)")
        if not args.file.is_file():
            raise CliError(f"--file: {args.file} does not exist")
        try:
            return load_scenario(args.file)
        except (ScenarioError, ValueError, OSError) as exc:
            raise CliError(f"--file: {exc}") from None
    if args.family is None:
        raise CliError("give a scenario FAMILY (see 'ft-sitl scenarios list') or --file SPEC")
    try:
        family = resolve_family(args.family)
    except ScenarioError as exc:
        raise CliError(str(exc)) from None
    index = 1 if args.index is None else args.index
    seed = 0 if args.seed is None else args.seed
    lo, hi = INDEX_RANGE
    if not lo <= index <= hi:
        raise CliError(f"--index: {index} must be within {lo}..{hi} (the paper's ten "
                       "configurations)")
    if seed < 0:
        raise CliError(f"--seed: {seed} must be a non-negative integer")
    try:
        return build_scenario(family, index, seed)
    except ScenarioError as exc:
        raise CliError(str(exc)) from None



def _difficulty_options(args, seed_option: bool = True) -> int | None:
    """The seed --difficulty measures (None without --difficulty); the options that need
    --difficulty are refused without it. ``seed_option``: --seed belongs to --difficulty
    (list, show; build's --seed names the scenario)."""
    seed = args.seed if seed_option else None
    if not args.difficulty:
        given = [name for name, value in (("--seed", seed), ("--no-cache", args.no_cache))
                 if value not in (None, False)]
        if given:
            verb = "applies" if len(given) == 1 else "apply"
            raise CliError(f"{' and '.join(given)} only {verb} with --difficulty")
        return None
    seed = 0 if seed is None else seed
    if seed < 0:
        raise CliError(f"--seed: {seed} must be a non-negative integer")
    return seed


def _measure(scenarios, args, what: str) -> list[Difficulty]:
    """The difficulty of each scenario built by the ``scenarios`` callables, with a
    progress bar on a terminal."""
    platform, budget = largest_platform(), flight_budget()
    cache = None if args.no_cache else default_cache_dir()
    out = []
    with tqdm(total=len(scenarios), desc=what, unit="config", dynamic_ncols=True,
              disable=None if len(scenarios) > 1 else True) as bar:
        for make in scenarios:
            sc = make()
            bar.set_postfix_str(sc.name, refresh=False)
            try:
                out.append(cached_difficulty(sc, platform, budget, cache))
            except OSError as exc:
                raise CliError(f"cannot write the difficulty cache in {cache}: {exc} "
                               "(--no-cache measures without it)") from None
            bar.update()
    return out


def _span(pair, fmt: str) -> str:
    if pair is None:
        return "-"
    lo, hi = (format(v, fmt) for v in pair)
    return lo if lo == hi else f"{lo}-{hi}"


def _budget_line(results: list[Difficulty]) -> str:
    b = results[0].budget
    return (f"for {results[0].platform}'s body (the largest), timed at {b.speed_m_s:g} m/s "
            f"and {b.acc_m_s2:g} m/s^2 within {b.time_s:g} s")


def cmd_scenarios_list(args) -> int:
    seed = _difficulty_options(args)
    rows = []
    for key, builder in FAMILIES.items():
        sc = build_scenario(key, 1, 0)  # the area and ceiling do not depend on index or seed
        doc = (inspect.getdoc(builder) or "").splitlines()
        rows.append({
            "family": key,
            "paper_name": PAPER_NAMES[key],
            "category": CATEGORY[key],
            "area_m": [float(v) for v in sc.size[:2]],
            "ceiling_m": sc.ceiling,
            "description": SCENARIO_DESCRIPTIONS.get(key, doc[0] if doc else ""),
        })
    measured = {}
    if seed is not None:
        lo, hi = INDEX_RANGE
        jobs = [(key, i) for key in FAMILIES for i in range(lo, hi + 1)]
        results = _measure([lambda k=k, i=i: build_scenario(k, i, seed) for k, i in jobs],
                           args, "difficulty")
        for (key, _), d in zip(jobs, results):
            measured.setdefault(key, []).append(d)
        for r in rows:
            found = measured[r["family"]]
            r["difficulty"] = {"seed": seed, "summary": summarise(found),
                               "configurations": [d.as_dict() for d in found]}
    if args.json:
        print(json.dumps(rows, indent=2))
        return 0
    print(f"{'family':22s} {'paper name':22s} {'category':11s} {'area (m)':>9s} {'ceiling':>7s}"
          f"  description")
    for r in rows:
        area = f"{r['area_m'][0]:g} x {r['area_m'][1]:g}"
        print(f"{r['family']:22s} {r['paper_name']:22s} {r['category']:11s} {area:>9s} "
              f"{r['ceiling_m']:5g} m  {r['description']}")
    print(f"{len(rows)} families, configurations (--index) {INDEX_RANGE[0]}.."
          f"{INDEX_RANGE[1]}, any --seed >= 0")
    if measured:
        first = next(iter(measured.values()))
        print(f"\ndifficulty of configurations {INDEX_RANGE[0]}..{INDEX_RANGE[1]}, seed {seed}, "
              f"{_budget_line(first)} (ranges over each family):")
        print(f"{'family':22s} {'in budget':>9s} {'path/line':>11s} {'turns':>6s} "
              f"{'narrowest (m)':>13s} {'spare (m)':>10s} {'obstacles':>9s} {'filled %':>9s} "
              f"{'time (s)':>11s}")
        for key, found in measured.items():
            sm = summarise(found)
            filled = [100 * v for v in sm["occupied_fraction"]]
            print(f"{key:22s} {sm['flyable']:>6d}/{sm['configurations']:<2d} "
                  f"{_span(sm['path_ratio'], '.2f'):>11s} {_span(sm['turns'], 'd'):>6s} "
                  f"{_span(sm['passage_width_m'], '.2f'):>13s} "
                  f"{_span(sm['passage_spare_m'], '.2f'):>10s} "
                  f"{_span(sm['obstacle_count'], 'd'):>9s} {_span(filled, '.1f'):>9s} "
                  f"{_span(sm['time_s'], '.1f'):>11s}")
    return 0


def _difficulty_rows(results: list[Difficulty]) -> None:
    print(f"{'config':28s} {'path (m)':>8s} {'/line':>6s} {'turns':>5s} {'narrowest':>9s} "
          f"{'spare':>6s} {'obstacles':>9s} {'/100m2':>6s} {'filled':>7s} {'time (s)':>8s}  "
          f"in budget")
    for d in results:
        print(f"{d.scenario:28s} {num(d.path_m, '.1f'):>8s} {num(d.path_ratio, '.2f'):>6s} "
              f"{num(d.turns, 'd'):>5s} {num(d.passage_width_m, '.3f'):>9s} "
              f"{num(d.passage_spare_m, '.3f'):>6s} {d.obstacle_count:>9d} "
              f"{d.obstacles_per_100m2:>6.2f} {100 * d.occupied_fraction:>6.1f}% "
              f"{num(d.time_s, '.1f'):>8s}  {'yes' if d.flyable else 'NO'}")


def cmd_scenarios_show(args) -> int:
    """One family's declared generator parameters (its schema), and with --difficulty
    the measured difficulty of its configurations."""
    try:
        fam = describe_family(args.family)
    except ScenarioError as exc:
        raise CliError(str(exc)) from None
    seed = _difficulty_options(args)
    rows = fam.schema.rows()
    results = []
    if seed is not None:
        lo, hi = INDEX_RANGE
        results = _measure([lambda i=i: build_scenario(fam.name, i, seed)
                            for i in range(lo, hi + 1)], args, fam.name)
    if args.json:
        doc = {"family": fam.name, "paper_name": fam.paper_name, "category": fam.category,
               "parameters": rows}
        if results:
            doc["difficulty"] = {"seed": seed, "summary": summarise(results),
                                 "configurations": [d.as_dict() for d in results]}
        print(json.dumps(doc, indent=2))
        return 0
    n = f"{len(rows)} generator parameter{'s' if len(rows) != 1 else ''}"
    print(f"{fam.name} ({fam.paper_name}, {fam.category}): {n} (drawn per configuration "
          f"within these ranges)")
    print_schema_rows(rows)
    if results:
        print(f"\ndifficulty, seed {seed}, {_budget_line(results)}:")
        _difficulty_rows(results)
    return 0


def cmd_scenarios_build(args) -> int:
    _difficulty_options(args, seed_option=False)
    t0 = time.perf_counter()
    sc = _scenario_from_args(args)
    build_s = time.perf_counter() - t0
    d = _measure([lambda: sc], args, sc.name)[0] if args.difficulty else None
    if args.json:
        doc = sc.summary()
        if d is not None:
            doc["difficulty"] = d.as_dict()
        print(json.dumps(doc, indent=2))
        return 0
    paper = PAPER_NAMES.get(sc.family, sc.family)
    w, l, h = sc.size
    print(f"{sc.name}  ({paper}, {sc.category})")
    print(f"  area {w:g} x {l:g} m, ceiling {h:g} m")
    print(f"  obstacles {sc.obstacle_count}: {len(sc.mesh.vertices)} vertices, "
          f"{len(sc.mesh.faces)} triangles")
    print(f"  takeoff {fmt_point(sc.takeoff)}")
    print(f"  start   {fmt_point(sc.start)}, yaw {math.degrees(sc.start_yaw):.1f} deg")
    print(f"  goal    {fmt_point(sc.goal)}, radius {sc.goal_radius_m:g} m, straight line "
          f"{math.dist(sc.goal, sc.start):.1f} m")
    print(f"  mesh sha256 {sc.mesh_digest()}")
    print(f"  {'loaded' if args.file is not None else 'built'} in {build_s:.3f} s")
    if d is not None:
        _print_difficulty(d)
    return 0


def _print_difficulty(d: Difficulty) -> None:
    print(f"  difficulty {_budget_line([d])}:")
    if d.path_m is None:
        print(f"    no path found for the body (grid pitch: docs/scenarios.md); obstacles "
              f"{d.obstacle_count}, {100 * d.occupied_fraction:.2f} % of the volume filled")
        return
    angles = ", ".join(f"{a:.0f}" for a in d.turn_angles_deg if a > TURN_DEG)
    print(f"    shortest path {d.path_m:.2f} m, {d.path_ratio:.3f} x the straight line "
          f"({d.straight_m:.2f} m), body yaw {d.body_yaw_deg:.1f} deg")
    print(f"    turns over {TURN_DEG:g} deg: {d.turns}" + (f" ({angles} deg)" if angles else ""))
    print(f"    narrowest passage {d.passage_width_m:.3f} m wide, {d.passage_spare_m:.3f} m "
          f"to spare, at {fmt_point(d.passage_point)} across "
          f"{fmt_point(d.passage_direction)}")
    print(f"    obstacles {d.obstacle_count} ({d.obstacles_per_100m2:.2f} per 100 m^2, "
          f"{d.mesh_pieces} convex pieces), {100 * d.occupied_fraction:.2f} % of the flight "
          f"volume filled")
    verdict = "within the budget" if d.flyable else "OVER the budget"
    print(f"    flight time at best {d.time_s:.1f} s of {d.budget.time_s:g} s: {verdict}")


def cmd_scenarios_export(args) -> int:
    valid = ", ".join(EXPORT_FORMATS)
    fmt = args.format
    if fmt is None:
        suffix = args.out.suffix.lower().lstrip(".") if args.out is not None else ""
        if suffix not in EXPORT_FORMATS:
            hint = f" (the --out suffix .{suffix} is not one)" if suffix else ""
            raise CliError(f"--format: give one of {valid}{hint}")
        fmt = suffix
    if fmt.lower() not in EXPORT_FORMATS:
        raise CliError(f"--format: {fmt!r} is not one of {valid}")
    fmt = fmt.lower()
    if args.out is not None:
        check_out_dir("--out", args.out)
    sc = _scenario_from_args(args)
    out = args.out if args.out is not None else Path(f"{sc.name}.{fmt}")
    try:
        written = [Path(p) for p in export_scenario(sc, out, fmt)]
        if args.spec:
            # the spec refers to an exact PLY: the one just written, or one written beside it
            mesh = written[0] if fmt == "ply" else None
            spec_files = write_scenario_spec(sc, written[0].with_suffix(".yaml"),
                                             mesh_path=mesh)
            written += [Path(p) for p in spec_files if Path(p) not in written]
    except (ScenarioError, ValueError, OSError) as exc:
        raise CliError(str(exc)) from None
    if args.json:
        print(json.dumps({"scenario": sc.name, "format": fmt,
                          "files": [str(p) for p in written]}, indent=2))
        return 0
    for p in written:
        print(f"wrote {p}")
    return 0


def cmd_scenarios_render(args) -> int:
    if args.out is not None:
        if args.out.suffix.lower() != ".png":
            raise CliError(f"--out: {args.out} must end in .png (the picture is a PNG)")
        check_out_dir("--out", args.out)
    if not DPI_RANGE[0] <= args.dpi <= DPI_RANGE[1]:
        raise CliError(f"--dpi: {args.dpi:g} must be within {DPI_RANGE[0]}..{DPI_RANGE[1]}")
    traj = None
    if args.trajectory is not None:
        try:
            traj = load_trajectory(args.trajectory)
        except ValueError as exc:
            raise CliError(f"--trajectory: {exc}") from None
    sc = _scenario_from_args(args)
    out = args.out if args.out is not None else Path(f"{sc.name}.png")
    try:
        render_scenario(sc, out, trajectory=traj, dpi=args.dpi)
    except OSError as exc:
        raise CliError(f"--out: cannot write {out}: {exc}") from None
    print(f"wrote {out}")
    return 0

