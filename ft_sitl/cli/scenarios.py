"""``ft-sitl scenarios``: list, build, export and draw the scenario families."""

from __future__ import annotations

import inspect
import json
import math
import time
from pathlib import Path

from ft_sitl.cli.common import CliError, check_out_dir, fmt_point, print_schema_rows
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
    "narrow_gap": "walls across the route, one 0.85-0.90 m gap each; index = walls",
    "sudden_drop": "overhanging blocks from 1.5 m up, start at 2.5 m; index = blocks",
    "maze": "a perfect maze with dead ends: one route to the goal",
    "perlin": "blobs of 0.25 m voxels where 3-D Perlin noise is in its top 3 %",
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



def cmd_scenarios_list(args) -> int:
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
    return 0


def cmd_scenarios_show(args) -> int:
    """One family's declared generator parameters (its schema)."""
    try:
        fam = describe_family(args.family)
    except ScenarioError as exc:
        raise CliError(str(exc)) from None
    rows = fam.schema.rows()
    if args.json:
        print(json.dumps({"family": fam.name, "paper_name": fam.paper_name,
                          "category": fam.category, "parameters": rows}, indent=2))
        return 0
    n = f"{len(rows)} generator parameter{'s' if len(rows) != 1 else ''}"
    print(f"{fam.name} ({fam.paper_name}, {fam.category}): {n} (drawn per configuration "
          f"within these ranges)")
    print_schema_rows(rows)
    return 0


def cmd_scenarios_build(args) -> int:
    t0 = time.perf_counter()
    sc = _scenario_from_args(args)
    build_s = time.perf_counter() - t0
    if args.json:
        print(json.dumps(sc.summary(), indent=2))
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
    return 0


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

