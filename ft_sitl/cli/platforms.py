"""``ft-sitl platforms``: the platform catalog (list, show, check, generate, series)."""

from __future__ import annotations

import json
import sys

from ft_sitl.cli.common import CliError, platform_registry
from ft_sitl.physics.catalog import as_file_entry, catalog, load_platform_file, to_toml
from ft_sitl.physics.platform import SCHEMA
from ft_sitl.physics.series import with_alpha_xy, with_twr
from ft_sitl.physics.synthesis import generate_virtual


def _platform_row(p) -> dict:
    ind = p.indicators()
    return {
        "name": p.name,
        "category": p.category,
        "mass_kg": p.mass_kg,
        "layout": p.layout,
        "twr_max": round(ind.twr_max, 4),
        "alpha_xy_max_rad_s2": round(ind.alpha_xy_max_rad_s2, 3),
        "alpha_z_max_rad_s2": round(ind.alpha_z_max_rad_s2, 3),
    }


def cmd_platforms_list(args) -> int:
    plats = platform_registry(args).all(with_series=True)
    if args.category:
        plats = [p for p in plats if p.category == args.category]
    rows = [_platform_row(p) for p in plats]
    if args.json:
        print(json.dumps(rows, indent=2))
        return 0
    w = max([28] + [len(r["name"]) for r in rows])
    print(f"{'name':{w}s} {'category':8s} {'mass kg':>8s} {'TWR_max':>8s} "
          f"{'a_xy rad/s2':>12s} {'a_z rad/s2':>11s}")
    for r in rows:
        print(f"{r['name']:{w}s} {r['category']:8s} {r['mass_kg']:8.3f} {r['twr_max']:8.2f} "
              f"{r['alpha_xy_max_rad_s2']:12.1f} {r['alpha_z_max_rad_s2']:11.1f}")
    print(f"{len(rows)} platforms")
    return 0


def cmd_platforms_show(args) -> int:
    p = platform_registry(args).get(args.name)
    row = _platform_row(p)
    phys = p.physical_dict()
    if args.json:
        out = {"indicators": {k: row[k] for k in
                              ("twr_max", "alpha_xy_max_rad_s2", "alpha_z_max_rad_s2")},
               "alpha_pitch_max_rad_s2": p.indicators().alpha_pitch_max_rad_s2,
               "hover_rotor_speed_rad_s": p.hover_rotor_speed_rad_s,
               "physical": phys, "body": p.body().describe()}
        print(json.dumps(out, indent=2))
        return 0
    print(f"{p.name}  ({p.category}, {p.layout})")
    print(f"  TWR_max {row['twr_max']:.3f}   alpha_xy,max {row['alpha_xy_max_rad_s2']:.2f} "
          f"rad/s^2   alpha_z,max {row['alpha_z_max_rad_s2']:.2f} rad/s^2")
    for key, spec in SCHEMA.items():
        v = phys[key]
        val = ", ".join(f"{x:.6g}" for x in v) if isinstance(v, list) else f"{v:.6g}"
        print(f"  {key:24s} {val:>36s} {spec.unit}")
    print(f"  {'hover rotor speed':24s} {p.hover_rotor_speed_rad_s:>36.6g} rad/s")
    body = p.body().describe()
    print("  collision body (protocol 5 on; * = set by the platform, else its rule):")
    for key, label in (("body_size_m", "central body box"),
                       ("rotor_disk_radius_m", "rotor disk radius"),
                       ("rotor_disk_thickness_m", "rotor disk thickness"),
                       ("rotor_height_m", "rotor plane height"),
                       ("bounding_radius_m", "bounding radius"),
                       ("half_span_m", "half span (footprint)"),
                       ("half_height_m", "half height")):
        v = body[key]
        val = ", ".join(f"{x:.4g}" for x in v) if isinstance(v, list) else f"{v:.4g}"
        mark = "*" if key in phys else " "
        print(f"  {mark} {label:22s} {val:>36s} m")
    if p.source:
        print(f"  source: {p.source}")
    return 0


def cmd_platforms_generate(args) -> int:
    base = [p for p in catalog().values() if args.base in ("all", p.category)]
    _write_platforms(args, generate_virtual(args.count, args.seed, base))
    return 0


def cmd_platforms_series(args) -> int:
    if not args.twr and not args.alpha_xy:
        raise CliError("series: give --twr and/or --alpha-xy values (docs/platforms.md, "
                       "Controlled platform series)")
    base = platform_registry(args).get(args.base)
    plats = [with_twr(base, t, category="user") for t in args.twr]
    plats += [with_alpha_xy(base, a, category="user") for a in args.alpha_xy]
    names = [p.name for p in plats]
    for name in names:
        if names.count(name) > 1:
            raise CliError(f"series: {name!r} is asked for twice")
    # through the user-file path: the same checks a platform file gets
    plats = [as_file_entry(p, "series") for p in plats]
    _write_platforms(args, plats)
    return 0


def _write_platforms(args, plats) -> None:
    """A TOML platform file of ``plats`` to --out or stdout (--json: their indicators)."""
    text = to_toml(plats)
    if args.out:
        if args.out.exists() and not args.force:
            raise CliError(f"--out: {args.out} exists (use --force to overwrite)")
        args.out.write_text(text, encoding="utf-8")
        print(f"wrote {len(plats)} platforms to {args.out}", file=sys.stderr)
    if args.json:
        print(json.dumps([_platform_row(p) for p in plats], indent=2))
    elif not args.out:
        print(text, end="")


def cmd_platforms_check(args) -> int:
    plats = load_platform_file(args.file)
    rows = [_platform_row(p) for p in plats]
    if args.json:
        print(json.dumps(rows, indent=2))
    else:
        for r in rows:
            print(f"ok  {r['name']}: TWR_max {r['twr_max']:.2f}, alpha_xy "
                  f"{r['alpha_xy_max_rad_s2']:.1f}, alpha_z {r['alpha_z_max_rad_s2']:.1f}")
    return 0

