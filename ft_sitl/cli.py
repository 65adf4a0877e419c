"""The ``ft-sitl`` command.

Every subcommand prints human-readable text by default; list-type commands take
``--json`` for machine-readable output. Errors are one line on stderr naming what was
wrong, with exit status 2 for bad input.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from ft_sitl import __version__

EXIT_BAD_INPUT = 2


class CliError(Exception):
    """Bad input from the command line: printed as one line, exit status 2."""


def _registry(args):
    from ft_sitl.physics.catalog import PlatformRegistry

    return PlatformRegistry(args.platform_file or ())


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
    plats = _registry(args).all()
    if args.category:
        plats = [p for p in plats if p.category == args.category]
    rows = [_platform_row(p) for p in plats]
    if args.json:
        print(json.dumps(rows, indent=2))
        return 0
    print(f"{'name':28s} {'category':8s} {'mass kg':>8s} {'TWR_max':>8s} "
          f"{'a_xy rad/s2':>12s} {'a_z rad/s2':>11s}")
    for r in rows:
        print(f"{r['name']:28s} {r['category']:8s} {r['mass_kg']:8.3f} {r['twr_max']:8.2f} "
              f"{r['alpha_xy_max_rad_s2']:12.1f} {r['alpha_z_max_rad_s2']:11.1f}")
    print(f"{len(rows)} platforms")
    return 0


def cmd_platforms_show(args) -> int:
    from ft_sitl.physics.platform import SCHEMA

    p = _registry(args).get(args.name)
    row = _platform_row(p)
    phys = p.physical_dict()
    if args.json:
        out = {"indicators": {k: row[k] for k in
                              ("twr_max", "alpha_xy_max_rad_s2", "alpha_z_max_rad_s2")},
               "alpha_pitch_max_rad_s2": p.indicators().alpha_pitch_max_rad_s2,
               "hover_rotor_speed_rad_s": p.hover_rotor_speed_rad_s,
               "physical": phys}
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
    if p.source:
        print(f"  source: {p.source}")
    return 0


def cmd_platforms_generate(args) -> int:
    from ft_sitl.physics.catalog import catalog, to_toml
    from ft_sitl.physics.synthesis import generate_virtual

    base = [p for p in catalog().values() if args.base in ("all", p.category)]
    plats = generate_virtual(args.count, args.seed, base)
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
    return 0


def cmd_platforms_check(args) -> int:
    from ft_sitl.physics.catalog import load_platform_file

    plats = load_platform_file(args.file)
    rows = [_platform_row(p) for p in plats]
    if args.json:
        print(json.dumps(rows, indent=2))
    else:
        for r in rows:
            print(f"ok  {r['name']}: TWR_max {r['twr_max']:.2f}, alpha_xy "
                  f"{r['alpha_xy_max_rad_s2']:.1f}, alpha_z {r['alpha_z_max_rad_s2']:.1f}")
    return 0


def cmd_params_list(args) -> int:
    from ft_sitl.autopilot.params import PARAMS

    rows = [{"name": s.name, "default": s.default, "min": s.lo, "max": s.hi, "unit": s.unit,
             "description": s.doc} for s in PARAMS.values()]
    if args.json:
        print(json.dumps(rows, indent=2))
        return 0
    for r in rows:
        print(f"{r['name']:18s} {r['default']:>8g}  [{r['min']:g}, {r['max']:g}] {r['unit']:12s}"
              f" {r['description']}")
    return 0


def cmd_demo(args) -> int:
    from ft_sitl.demo import plot_demo, run_demo

    p = _registry(args).get(args.platform)
    if args.plot and not args.plot.parent.is_dir():
        raise CliError(f"--plot: directory {args.plot.parent} does not exist")
    result = run_demo(p)
    if args.plot:
        try:
            plot_demo(result, str(args.plot))
        except (OSError, ValueError) as exc:
            raise CliError(f"--plot: cannot write {args.plot}: {exc}") from None
    if args.json:
        print(json.dumps(result.summary(), indent=2))
        return 0
    print(f"ft-sitl {__version__} demo flight: {p.name} "
          f"(TWR_max {p.indicators().twr_max:.2f}, {p.mass_kg} kg), physics 1 kHz, lockstep")
    print(f"{'phase':8s} {'t (s)':>11s}  {'command':42s} {'end position ENU (m)':>24s} "
          f"{'yaw':>7s} {'vmax':>6s} {'tilt':>6s}")
    for ph in result.phases:
        pos = "(" + ", ".join(f"{v:.2f}" for v in ph.end_position_enu_m) + ")"
        print(f"{ph.name:8s} {ph.t_start_s:5.1f}-{ph.t_end_s:<5.1f}  {ph.command:42s} {pos:>24s} "
              f"{ph.end_yaw_deg:6.1f}° {ph.max_speed_m_s:5.2f} {ph.max_tilt_deg:5.1f}°")
    print(f"landed: {'yes' if result.landed else 'NO'}, touchdown speed "
          f"{result.max_impact_speed_m_s:.2f} m/s, rotor energy {result.energy_j:.0f} J")
    print(f"{result.sim_time_s:.1f} s simulated in {result.wall_time_s:.3f} s wall "
          f"({result.speed_up:.0f}x real time)")
    if args.plot:
        print(f"plot: {args.plot}")
    return 0


def _parse_home(text: str):
    from ft_sitl.frames import GeoReference

    parts = text.split(",")
    if len(parts) != 3:
        raise CliError(f"--home: {text!r} must be LAT,LON,ALT (degrees, degrees, metres AMSL)")
    try:
        lat, lon, alt = (float(v) for v in parts)
    except ValueError:
        raise CliError(f"--home: {text!r} has a value that is not a number") from None
    try:
        return GeoReference(lat, lon, alt)
    except ValueError as exc:
        raise CliError(f"--home: {exc}") from None


def cmd_sitl(args) -> int:
    import asyncio
    import ipaddress
    import signal

    from ft_sitl.autopilot.fleet import Fleet
    from ft_sitl.frames import PX4_SITL_HOME, GeoReference
    from ft_sitl.mavlink.server import SitlServer

    if not 1 <= args.instances <= 64:
        raise CliError(f"--instances: {args.instances} must be within 1..64")
    geo = _parse_home(args.home) if args.home else GeoReference(*PX4_SITL_HOME)
    try:
        loopback = ipaddress.ip_address(args.bind).is_loopback
    except ValueError:
        raise CliError(f"--bind: {args.bind!r} is not an IP address") from None
    p = _registry(args).get(args.platform)
    fleet = Fleet([p] * args.instances,
                  spawn=[[0.0, 2.0 * i, 0.0] for i in range(args.instances)])
    try:
        server = SitlServer(fleet, geo, bind=args.bind, speed_factor=args.speed_factor,
                            tlog=args.tlog, signing_key=args.signing_key)
    except (ValueError, OSError) as exc:
        raise CliError(str(exc)) from None
    urls = server.urls()
    if args.json:
        print(json.dumps({"platform": p.name, "vehicles": urls}, indent=2), flush=True)
    else:
        print(f"ft-sitl {__version__}: {args.instances} x {p.name}, speed factor "
              f"{args.speed_factor:g}, home {geo.lat_deg:.6f}, {geo.lon_deg:.6f}, "
              f"{geo.alt_m:.1f} m", flush=True)
        if not loopback:
            print(f"warning: listening on {args.bind}, reachable from other machines",
                  flush=True)
        for u in urls:
            print(f"  vehicle sysid {u['sysid']}: MAVSDK {u['mavsdk']}   pymavlink "
                  f"{u['pymavlink']}   GCS {u['gcs']}", flush=True)
        print("Ctrl-C stops.", flush=True)

    async def main():
        try:
            await server.start()
        except OSError as exc:
            raise CliError(f"cannot listen on {args.bind}: {exc.strerror}") from None
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.add_signal_handler(sig, server.stop)
        try:
            await server.run(duration_s=args.duration)
        finally:
            server.close()

    asyncio.run(main())
    sim_s = fleet.time_us * 1e-6
    print(f"stopped after {sim_s:.1f} s simulated; achieved speed factor "
          f"{server.achieved_speed_factor:.2f} (asked {args.speed_factor:g}); "
          f"{server.bad_packets} bad packets dropped", file=sys.stderr)
    return 0


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(
        prog="ft-sitl",
        description="FLYINGTRUST quadrotor SITL: platforms, rotor dynamics and a virtual PX4.",
    )
    ap.add_argument("--version", action="version", version=f"ft-sitl {__version__}")
    pf = argparse.ArgumentParser(add_help=False)
    pf.add_argument("--platform-file", action="append", type=Path, metavar="FILE",
                    help="add user platforms from a TOML/YAML file (repeatable)")
    sub = ap.add_subparsers(dest="command", metavar="COMMAND", required=True)

    demo = sub.add_parser("demo", parents=[pf], help="fly a short demo flight and report it",
                          description="Arm, take off to 2 m, fly an 8 m leg, turn 90 deg, "
                          "descend and land, in lockstep at 1 kHz; print each phase.")
    demo.add_argument("--platform", default="0.98kg-EGO Planner DIY",
                      help="platform name (default: %(default)s)")
    demo.add_argument("--plot", type=Path, metavar="PNG", help="save a plot of the flight")
    demo.add_argument("--json", action="store_true", help="machine-readable output")
    demo.set_defaults(func=cmd_demo)

    plat = sub.add_parser("platforms", help="the platform catalog",
                          description="List, show, check and generate platforms.")
    psub = plat.add_subparsers(dest="platforms_command", metavar="ACTION", required=True)
    pl = psub.add_parser("list", parents=[pf], help="list platforms with their indicators")
    pl.add_argument("--category", choices=("real", "virtual", "user"))
    pl.add_argument("--json", action="store_true", help="machine-readable output")
    pl.set_defaults(func=cmd_platforms_list)
    ps = psub.add_parser("show", parents=[pf], help="show one platform's physical parameters")
    ps.add_argument("name")
    ps.add_argument("--json", action="store_true", help="machine-readable output")
    ps.set_defaults(func=cmd_platforms_show)
    pc = psub.add_parser("check", help="validate a user platform file")
    pc.add_argument("file", type=Path)
    pc.add_argument("--json", action="store_true", help="machine-readable output")
    pc.set_defaults(func=cmd_platforms_check)
    pg = psub.add_parser("generate", help="generate new virtual platforms by interpolation",
                         description="Random convex combinations (in log space) of catalog "
                         "platforms' mass and indicators, synthesised and validated.")
    pg.add_argument("--count", type=int, default=5, help="how many (default: %(default)s)")
    pg.add_argument("--seed", type=int, default=0, help="random seed (default: %(default)s)")
    pg.add_argument("--base", choices=("real", "virtual", "all"), default="virtual",
                    help="which catalog platforms span the design space (default: %(default)s)")
    pg.add_argument("--out", type=Path, help="write a TOML platform file instead of stdout")
    pg.add_argument("--force", action="store_true", help="overwrite --out if it exists")
    pg.add_argument("--json", action="store_true", help="print the generated indicators as JSON")
    pg.set_defaults(func=cmd_platforms_generate)

    sitl = sub.add_parser(
        "sitl", parents=[pf], help="serve vehicles over MAVLink like PX4 SITL",
        description="Start N simulated vehicles with PX4 SITL's UDP ports: vehicle i (sysid "
        "i+1) sends to 127.0.0.1:14540+i (MAVSDK, listens on 14580+i) and to "
        "127.0.0.1:14550 (GCS, listens on 18570+i).")
    sitl.add_argument("--platform", default="0.98kg-EGO Planner DIY",
                      help="platform name (default: %(default)s)")
    sitl.add_argument("--instances", type=int, default=1, help="number of vehicles (1..64)")
    sitl.add_argument("--speed-factor", type=float, default=1.0,
                      help="simulated seconds per wall second (default: 1)")
    sitl.add_argument("--home", metavar="LAT,LON,ALT",
                      help="geodetic home (default: PX4 SITL's 47.397742,8.545594,488)")
    sitl.add_argument("--bind", default="127.0.0.1",
                      help="address to listen on (default: loopback only)")
    sitl.add_argument("--tlog", type=Path, metavar="PATH",
                      help="record all MAVLink traffic as a telemetry log")
    sitl.add_argument("--signing-key", metavar="KEY",
                      help="MAVLink 2 signing passphrase: unsigned packets are rejected")
    sitl.add_argument("--duration", type=float, metavar="S",
                      help="stop after S wall seconds (default: run until Ctrl-C)")
    sitl.add_argument("--json", action="store_true", help="print the vehicle URLs as JSON")
    sitl.set_defaults(func=cmd_sitl)

    par = sub.add_parser("params", help="flight-controller parameters")
    parsub = par.add_subparsers(dest="params_command", metavar="ACTION", required=True)
    parl = parsub.add_parser("list", help="list PX4-named parameters with defaults and bounds")
    parl.add_argument("--json", action="store_true", help="machine-readable output")
    parl.set_defaults(func=cmd_params_list)
    return ap


def main(argv: list[str] | None = None) -> int:
    from ft_sitl.autopilot.params import ParamError
    from ft_sitl.autopilot.setpoints import SetpointError
    from ft_sitl.physics.platform import PlatformError

    ap = build_parser()
    args = ap.parse_args(argv)
    try:
        return args.func(args)
    except (CliError, PlatformError, ParamError, SetpointError) as exc:
        print(f"ft-sitl: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except BrokenPipeError:
        return 0


if __name__ == "__main__":
    sys.exit(main())
