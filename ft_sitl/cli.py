"""The ``ft-sitl`` command.

Every subcommand prints human-readable text by default; list-type commands take
``--json`` for machine-readable output. Errors are one line on stderr naming what was
wrong, with exit status 2 for bad input.
"""

from __future__ import annotations

import argparse
import json
import math
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


def _ned(v) -> str:
    return "[" + ", ".join(f"{x:.2f}" for x in v) + "]"


def _heading_deg(yaw_enu: float) -> float:
    from ft_sitl.frames import yaw_enu_to_ned

    return math.degrees(yaw_enu_to_ned(yaw_enu)) % 360.0


def _sitl_scenario(text: str):
    """``FAMILY:INDEX[:SEED]`` or a scenario spec file -> Scenario."""
    from ft_sitl.scenarios.io import scenario_from_spec

    try:
        return scenario_from_spec(text)
    except ValueError as exc:
        raise CliError(f"--scenario: {exc}") from None


def _sitl_bus(args, server, fleet, scenario):
    """The MQTT bus of ``ft-sitl sitl``: one SitlBus per vehicle on the user's broker or
    an embedded one; none with --no-mqtt."""
    if args.no_mqtt:
        return [], None
    from ft_sitl.bus.options import TlsOptions, parse_broker_url
    from ft_sitl.bus.publisher import BusPublisher
    from ft_sitl.navigation.common import camera_config
    from ft_sitl.wire.sitl_bus import SitlBus

    tls = None
    if any((args.mqtt_ca, args.mqtt_cert, args.mqtt_key, args.mqtt_insecure)):
        try:
            tls = TlsOptions(args.mqtt_ca, args.mqtt_cert, args.mqtt_key, args.mqtt_insecure)
        except ValueError as exc:
            raise CliError(f"--mqtt TLS options: {exc}") from None
    broker = None
    if args.mqtt:
        try:
            opts = parse_broker_url(args.mqtt, tls)
        except ValueError as exc:
            raise CliError(f"--mqtt: {exc}") from None
    else:
        if tls is not None:
            raise CliError("--mqtt-ca/--mqtt-cert/--mqtt-key/--mqtt-insecure need --mqtt "
                           "mqtts://...")
        from ft_sitl.bus.broker import EmbeddedBroker

        try:
            broker = EmbeddedBroker().start()
        except Exception as exc:  # noqa: BLE001 - amqtt failing must not stop the SITL
            print(f"warning: no MQTT bus: the embedded broker did not start ({exc})",
                  file=sys.stderr)
            return [], None
        opts = parse_broker_url(broker.url)
    if not 1.0 <= args.telemetry_rate <= 1000.0:
        raise CliError(f"--telemetry-rate: {args.telemetry_rate} must be within 1..1000 Hz")
    cam = None
    if scenario is not None and args.camera != "none":
        cam = camera_config(args.camera, None, None, None)
    buses = []
    for i in range(fleet.n):
        vid = str(server.base_instance + i)
        buses.append(SitlBus(lambda on_config, vid=vid: BusPublisher(opts, vid,
                                                                      on_config=on_config),
                             fleet, i, scenario=scenario, camera_config=cam,
                             telemetry_rate_hz=args.telemetry_rate))
    # start publishing connected (later outages only cost dropped messages, counted)
    if buses and not all(b.pub.wait_connected(10.0) for b in buses):
        print(f"warning: MQTT broker {opts.url} not reachable yet; the bus keeps trying "
              "(messages are dropped and counted until it connects)", file=sys.stderr)
    return buses, broker


def _scenario_spawn(scenario, platform, n: int):
    """Spawn points: the scenario's takeoff point, further vehicles 1.5 m apart across the
    start direction; each must be clear of the obstacles."""
    import numpy as np

    from ft_sitl.scenarios.collision import CollisionWorld

    yaw = scenario.start_yaw
    across = np.array([-math.sin(yaw), math.cos(yaw), 0.0])
    world = CollisionWorld(scenario.mesh, scenario.bounds_min, scenario.bounds_max)
    r = platform.collision_radius_m
    spawn = []
    for k in range(n):
        off = 1.5 * ((k + 1) // 2) * (1 if k % 2 else -1)
        pos = scenario.takeoff + off * across
        centre = pos + np.array([0.0, 0.0, r + 0.01])
        if world.clearance(centre, r, kinds=("obstacle", "bounds")) <= 0.0:
            raise CliError(f"--instances: vehicle {k + 1}'s spawn point "
                           f"{np.round(pos, 2).tolist()} in {scenario.name} is blocked by an "
                           f"obstacle or outside the area; use fewer instances")
        spawn.append(pos.tolist())
    return spawn, [yaw] * n


def cmd_sitl(args) -> int:
    import asyncio
    import ipaddress
    import signal

    from ft_sitl.frames import PX4_SITL_HOME, GeoReference
    from ft_sitl.mavlink.server import SitlServer
    from ft_sitl.sim.fleet import Fleet

    if not 1 <= args.instances <= 64:
        raise CliError(f"--instances: {args.instances} must be within 1..64")
    if not 0 <= args.instance <= 1000 - args.instances:
        raise CliError(f"--instance: {args.instance} must be within 0..{1000 - args.instances}")
    geo = _parse_home(args.home) if args.home else GeoReference(*PX4_SITL_HOME)
    try:
        loopback = ipaddress.ip_address(args.bind).is_loopback
    except ValueError:
        raise CliError(f"--bind: {args.bind!r} is not an IP address") from None
    p = _registry(args).get(args.platform)
    scenario = _sitl_scenario(args.scenario) if args.scenario else None
    if scenario is None:
        spawn = [[0.0, 2.0 * i, 0.0] for i in range(args.instances)]
        yaw = [0.0] * args.instances
    else:
        spawn, yaw = _scenario_spawn(scenario, p, args.instances)
    fleet = Fleet([p] * args.instances, spawn=spawn, spawn_yaw=yaw, scenario=scenario)
    try:
        server = SitlServer(fleet, geo, bind=args.bind, speed_factor=args.speed_factor,
                            tlog=args.tlog, signing_key=args.signing_key,
                            base_instance=args.instance)
    except (ValueError, OSError) as exc:
        raise CliError(str(exc)) from None
    urls = server.urls()
    buses, broker = _sitl_bus(args, server, fleet, scenario)
    for u, b in zip(urls, buses):
        u["mqtt"] = b.pub.url
        u["bus_vehicle"] = b.pub.vehicle
    if args.json:
        out = {"platform": p.name, "vehicles": urls}
        if scenario is not None:
            out["scenario"] = scenario.summary()
            out["spawn_enu"] = spawn
        print(json.dumps(out, indent=2), flush=True)
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
        if buses:
            where = "embedded broker" if broker is not None else "broker"
            print(f"MQTT bus ({where}) {buses[0].pub.url}: topics ft-sitl/v1/<vehicle>/..., "
                  f"vehicles {', '.join(b.pub.vehicle for b in buses)}", flush=True)
        if scenario is not None:
            from ft_sitl.frames import enu_to_ned

            o = scenario.takeoff
            print(f"scenario {scenario.name}: {scenario.obstacle_count} obstacles, ceiling "
                  f"{scenario.ceiling:g} m; in vehicle 1's local NED frame (origin = its "
                  f"takeoff point) start {_ned(enu_to_ned(scenario.start - o))}, goal "
                  f"{_ned(enu_to_ned(scenario.goal - o))}, start heading "
                  f"{_heading_deg(scenario.start_yaw):.1f} deg", flush=True)
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

    if buses:
        server.on_chunk = lambda: [b.service() for b in buses]
    try:
        asyncio.run(main())
    finally:
        for b in buses:
            st = b.stats()
            sent = sum(st.sent.values())
            dropped = ", ".join(f"{k} {v}" for k, v in st.dropped.items() if v) or "none"
            print(f"bus vehicle {b.pub.vehicle}: {sent} messages sent, dropped: {dropped}; "
                  f"{st.reconnects} reconnects", file=sys.stderr)
            b.close()
        if broker is not None:
            broker.stop()
    sim_s = fleet.time_us * 1e-6
    print(f"stopped after {sim_s:.1f} s simulated; achieved speed factor "
          f"{server.achieved_speed_factor:.2f} (asked {args.speed_factor:g}); "
          f"{server.bad_packets} bad packets dropped", file=sys.stderr)
    return 0


# --------------------------------------------------------------------------------------
# scenarios
# --------------------------------------------------------------------------------------

SCENARIO_DESCRIPTIONS = {
    "forest": "random upright tree trunks (paper density 1/49 per m^2)",
    "urban": "buildings on a street grid, plus free-standing walls",
    "random_angle_cylinder": "random cylinders tilted 0-180 deg (paper density 1/36 per m^2)",
    "narrow_gap": "walls across the route, one 0.85-0.90 m gap each; index = walls",
    "sudden_drop": "overhanging blocks from 1.5 m up, start at 2.5 m; index = blocks",
    "maze": "a perfect maze with dead ends: one route to the goal",
    "perlin": "blobs of 0.25 m voxels where 3-D Perlin noise is in its top 3 %",
}
"""One line per family for ``scenarios list`` (what it is made of and what index does)."""


def _check_out_dir(option: str, path: Path) -> None:
    parent = path.parent if str(path.parent) else Path(".")
    if not parent.is_dir():
        raise CliError(f"{option}: directory {parent} does not exist")


def _scenario_from_args(args):
    """The scenario the FAMILY / --file, --index, --seed options name."""
    from ft_sitl.scenarios.families import build_scenario, resolve_family
    from ft_sitl.scenarios.scenario import INDEX_RANGE, ScenarioError

    if args.file is not None:
        if args.family is not None:
            raise CliError(f"give a FAMILY or --file, not both (got {args.family!r} and "
                           f"--file {args.file})")
        if args.index is not None or args.seed is not None:
            raise CliError("--index and --seed do not apply to --file (the spec sets them)")
        if not args.file.is_file():
            raise CliError(f"--file: {args.file} does not exist")
        from ft_sitl.scenarios.io import load_scenario

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


def _fmt_point(p) -> str:
    return "(" + ", ".join(f"{v:.2f}" for v in p) + ")"


def cmd_scenarios_list(args) -> int:
    import inspect

    from ft_sitl.scenarios.families import CATEGORY, FAMILIES, PAPER_NAMES, build_scenario
    from ft_sitl.scenarios.scenario import INDEX_RANGE

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


def cmd_scenarios_build(args) -> int:
    import time

    from ft_sitl.scenarios.families import PAPER_NAMES

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
    print(f"  takeoff {_fmt_point(sc.takeoff)}")
    print(f"  start   {_fmt_point(sc.start)}, yaw {math.degrees(sc.start_yaw):.1f} deg")
    print(f"  goal    {_fmt_point(sc.goal)}, radius {sc.goal_radius_m:g} m, straight line "
          f"{math.dist(sc.goal, sc.start):.1f} m")
    print(f"  mesh sha256 {sc.mesh_digest()}")
    print(f"  {'loaded' if args.file is not None else 'built'} in {build_s:.3f} s")
    return 0


def cmd_scenarios_export(args) -> int:
    from ft_sitl.scenarios.io import EXPORT_FORMATS, export_scenario, write_scenario_spec
    from ft_sitl.scenarios.scenario import ScenarioError

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
        _check_out_dir("--out", args.out)
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
    from ft_sitl.scenarios.render import DPI_RANGE, load_trajectory, render_scenario

    if args.out is not None:
        if args.out.suffix.lower() != ".png":
            raise CliError(f"--out: {args.out} must end in .png (the picture is a PNG)")
        _check_out_dir("--out", args.out)
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


def _add_scenarios_parser(sub) -> None:
    from ft_sitl.scenarios.render import DEFAULT_DPI  # numpy only: cheap at start-up

    sc = sub.add_parser("scenarios", help="the navigation scenario families",
                        description="List, build, export and draw the seven FLYINGTRUST "
                        "scenario families (10 configurations each, any seed).")
    ssub = sc.add_subparsers(dest="scenarios_command", metavar="ACTION", required=True)
    src = argparse.ArgumentParser(add_help=False)
    src.add_argument("family", nargs="?", metavar="FAMILY",
                     help="family name, e.g. forest or the paper's Narrow-Gap")
    src.add_argument("--file", type=Path, metavar="SPEC",
                     help="a scenario spec file (.yaml or .toml) instead of FAMILY")
    src.add_argument("--index", type=int, help="configuration 1..10 (default: 1)")
    src.add_argument("--seed", type=int, help="random seed, >= 0 (default: 0)")

    sl = ssub.add_parser("list", help="list the scenario families")
    sl.add_argument("--json", action="store_true", help="machine-readable output")
    sl.set_defaults(func=cmd_scenarios_list)
    sb = ssub.add_parser("build", parents=[src], help="build one scenario and summarise it",
                         description="Build a scenario and print its summary.")
    sb.add_argument("--json", action="store_true", help="print Scenario.summary() as JSON")
    sb.set_defaults(func=cmd_scenarios_build)
    se = ssub.add_parser("export", parents=[src], help="write a scenario's mesh to a file",
                         description="Write a scenario's obstacle mesh as PLY, PCD, OBJ, "
                         "Collada (DAE) or a Gazebo SDF world.")
    se.add_argument("--format", metavar="FMT",
                    help="ply, pcd, obj, dae or sdf (default: from the --out suffix)")
    se.add_argument("-o", "--out", type=Path, metavar="PATH",
                    help="output file (default: <scenario name>.<FMT> here)")
    se.add_argument("--spec", action="store_true",
                    help="also write a YAML spec that 'scenarios ... --file' reads back "
                    "(<PATH stem>.yaml, with the exact mesh <PATH stem>.ply)")
    se.add_argument("--json", action="store_true", help="print the written files as JSON")
    se.set_defaults(func=cmd_scenarios_export)
    sr = ssub.add_parser("render", parents=[src], help="draw a scenario to a PNG",
                         description="Draw a top view and a perspective view of a scenario "
                         "(start, goal, straight line, optional trajectory) to a PNG.")
    sr.add_argument("-o", "--out", type=Path, metavar="PNG",
                    help="output picture (default: <scenario name>.png here)")
    sr.add_argument("--trajectory", type=Path, metavar="FILE",
                    help="draw a flown path: .csv (x,y,z columns) or .npy (N x 3), ENU m")
    sr.add_argument("--dpi", type=float, default=DEFAULT_DPI,
                    help="resolution, dots per inch (default: %(default)s)")
    sr.set_defaults(func=cmd_scenarios_render)


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
    sitl.add_argument("--mqtt", metavar="URL", help="MQTT broker for the bus "
                      "(mqtt://[user[:pass]@]host[:port] or mqtts://...; default: an "
                      "embedded broker on a free port)")
    sitl.add_argument("--mqtt-ca", metavar="FILE", help="CA bundle for mqtts://")
    sitl.add_argument("--mqtt-cert", metavar="FILE", help="client certificate for mqtts://")
    sitl.add_argument("--mqtt-key", metavar="FILE", help="client key for mqtts://")
    sitl.add_argument("--mqtt-insecure", action="store_true",
                      help="do not verify the broker's certificate (testing only)")
    sitl.add_argument("--no-mqtt", action="store_true", help="no MQTT bus")
    sitl.add_argument("--telemetry-rate", type=float, default=50.0, metavar="HZ",
                      help="bus telemetry rate in simulated Hz (default 50)")
    sitl.add_argument("--camera", choices=("benchmark", "d435", "none"), default="benchmark",
                      help="depth camera for bus depth frames with --scenario (default "
                           "benchmark: 160 x 120 @ 15 Hz)")
    sitl.add_argument("--instance", type=int, default=0, metavar="I",
                      help="first instance number, as PX4's -i: ports 14580+I, 14540+I, "
                           "18570+I (default 0)")
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
    sitl.add_argument("--scenario", metavar="FAMILY:INDEX[:SEED]|SPEC",
                      help="fly in a scenario world (e.g. forest:3, or a .yaml/.toml spec): "
                           "spawn at its takeoff point, crash on collision")
    sitl.add_argument("--json", action="store_true", help="print the vehicle URLs as JSON")
    sitl.set_defaults(func=cmd_sitl)

    par = sub.add_parser("params", help="flight-controller parameters")
    parsub = par.add_subparsers(dest="params_command", metavar="ACTION", required=True)
    parl = parsub.add_parser("list", help="list PX4-named parameters with defaults and bounds")
    parl.add_argument("--json", action="store_true", help="machine-readable output")
    parl.set_defaults(func=cmd_params_list)

    from ft_sitl.cli_bridge import add_parsers as add_bridge_parsers
    from ft_sitl.cli_missions import add_parsers
    from ft_sitl.cli_wire import add_parsers as add_wire_parsers

    add_parsers(sub)
    add_wire_parsers(sub)
    add_bridge_parsers(sub)

    _add_scenarios_parser(sub)
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
