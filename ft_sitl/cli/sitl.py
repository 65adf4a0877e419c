"""``ft-sitl sitl``: serve simulated vehicles over MAVLink like PX4 SITL, with the MQTT bus."""

from __future__ import annotations

import asyncio
import contextlib
import ipaddress
import json
import math
import signal
import sys

from ft_sitl import __version__
from ft_sitl.bus.broker import EmbeddedBroker
from ft_sitl.bus.options import TlsOptions, parse_broker_url
from ft_sitl.cli.common import (
    CliError,
    actuators_option,
    estimator_option,
    option_value,
    platform_registry,
    wind_option,
)
from ft_sitl.frames import PX4_SITL_HOME, GeoReference, enu_to_ned, yaw_enu_to_ned
from ft_sitl.mavlink.ardupilot import parm, waypoints
from ft_sitl.mavlink.ardupilot.server import (
    ArduPilotServer,
    parse_out,
    serial_ports_free,
    tcp_port_free,
    tcp_ports,
)
from ft_sitl.mavlink.instances import InstanceBusy, free_instances, instances_held
from ft_sitl.mavlink.ports import describe_holder, instance_ports, taken_message, taken_ports
from ft_sitl.mavlink.server import SitlServer, check_pacing
from ft_sitl.physics.actuators import Actuators
from ft_sitl.scenarios.io import scenario_from_spec
from ft_sitl.schema import SchemaError
from ft_sitl.sim.fleet import Fleet
from ft_sitl.sim.spawn import SpawnError, spawn_points
from ft_sitl.transport.sitl_bus import fleet_buses


def _parse_home(text: str):
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
    return math.degrees(yaw_enu_to_ned(yaw_enu)) % 360.0


def _sitl_bus(args, server, fleet, scenario):
    """The MQTT bus of ``ft-sitl sitl``: one SitlBus per vehicle on the user's broker or
    an embedded one; none with --no-mqtt."""
    if args.no_mqtt:
        return [], None
    tls = None
    if any((args.mqtt_ca, args.mqtt_cert, args.mqtt_key, args.mqtt_insecure)):
        tls = option_value("--mqtt TLS options", TlsOptions, args.mqtt_ca, args.mqtt_cert,
                           args.mqtt_key, args.mqtt_insecure)
    broker = None
    if args.mqtt:
        opts = option_value("--mqtt", parse_broker_url, args.mqtt, tls)
    else:
        if tls is not None:
            raise CliError("--mqtt-ca/--mqtt-cert/--mqtt-key/--mqtt-insecure need --mqtt "
                           "mqtts://...")
        try:
            broker = EmbeddedBroker().start()
        except Exception as exc:  # noqa: BLE001 - amqtt failing must not stop the SITL
            print(f"warning: no MQTT bus: the embedded broker did not start ({exc})",
                  file=sys.stderr)
            return [], None
        opts = parse_broker_url(broker.url)
    buses, connected = fleet_buses(opts, fleet, server.base_instance, scenario=scenario,
                                   camera=args.camera, telemetry_rate_hz=args.telemetry_rate)
    if buses and not connected:
        print(f"warning: MQTT broker {opts.url} not reachable yet; the bus keeps trying "
              "(messages are dropped and counted until it connects)", file=sys.stderr)
    return buses, broker


def cmd_sitl(args) -> int:
    # each option's own range is checked as it is parsed (cli.common.number)
    auto = args.instance == "auto"
    if not auto and args.instance > 1000 - args.instances:
        raise CliError(f"--instance: {args.instance} must be within 0..{1000 - args.instances}")
    try:
        check_pacing(args.speed_factor, args.pace, args.pace_span)
    except ValueError as exc:
        raise CliError(str(exc)) from None
    vehicles = _vehicles(args)  # every option checked before the ports are taken
    with contextlib.ExitStack() as held:
        try:  # its instance numbers, so that no trial over MAVLink of this machine takes them
            if auto:  # the lowest free run whose ports are free too (no client lingering on
                # 14540+i, no PX4 SITL or other program on the listen ports)
                args.instance = held.enter_context(free_instances(
                    args.instances, lambda i: _ports_free(args, i)))
            else:
                held.enter_context(instances_held(args.instance, args.instances))
        except InstanceBusy as exc:
            raise CliError(f"--instance: {exc}") from None
        _check_ports(args)
        return _serve(args, *vehicles)


def _ports_free(args, i: int) -> bool:
    """Whether instance i's ports are free for the face asked for."""
    if args.autopilot == "ardupilot":
        return serial_ports_free(i, args.bind)
    return not taken_ports(i, args.bind, client=True)


def _check_ports(args) -> None:
    """A CliError naming each listen port another program holds, and who."""
    if args.autopilot == "ardupilot":
        for i in range(args.instance, args.instance + args.instances):
            taken = [p for p in tcp_ports(i) if not tcp_port_free(args.bind, p)]
            if taken:
                raise CliError(f"cannot listen on {args.bind}: instance {i}'s TCP port "
                               f"{taken[0]} is taken ({describe_holder(taken[0])})")
        return
    for i in range(args.instance, args.instance + args.instances):
        taken = taken_ports(i, args.bind, client=False)
        if taken:
            raise CliError(f"cannot listen on {args.bind}: {taken_message(i, taken)}")


def _vehicles(args):
    """The options turned into the fleet to serve (a CliError naming a bad one); nothing
    is bound yet."""
    geo = _parse_home(args.home) if args.home else GeoReference(*PX4_SITL_HOME)
    try:
        loopback = ipaddress.ip_address(args.bind).is_loopback
    except ValueError:
        raise CliError(f"--bind: {args.bind!r} is not an IP address") from None
    p = platform_registry(args).get(args.platform)
    scenario = option_value("--scenario", scenario_from_spec, args.scenario) \
        if args.scenario else None
    try:
        spawn, yaw = spawn_points(args.instances, scenario, p.collision_radius_m)
    except SpawnError as exc:
        raise CliError(f"--instances: {exc}") from None
    fleet = Fleet([p] * args.instances, spawn=spawn, spawn_yaw=yaw, scenario=scenario)
    wind = wind_option(args.wind)
    estimator = estimator_option(args.estimator)
    actuators = actuators_option(args.actuators)
    for i in range(args.instances):
        fleet.sim.set_wind(i, wind, seed=args.wind_seed + i)
        fleet.sim.set_estimator(i, estimator, seed=args.wind_seed + i)
        try:  # (the motor numbers against the platform's motors)
            fleet.sim.set_actuators(i, Actuators(actuators, "--actuators", p.n_rotors),
                                    seed=args.wind_seed + i)
        except SchemaError as exc:
            raise CliError(str(exc)) from None
    return geo, loopback, p, scenario, spawn, fleet, wind, estimator, actuators


def _serve(args, geo, loopback, p, scenario, spawn, fleet, wind, estimator, actuators) -> int:
    try:
        kwargs = {}
        if args.autopilot == "ardupilot":
            kwargs["outs"] = [parse_out(o) for o in args.out]
        elif args.out or args.mission or args.mission_out or args.defaults:
            what = "--out" if args.out else "--mission" if args.mission else \
                "--mission-out" if args.mission_out else "--defaults"
            raise ValueError(f"{what}: only with --autopilot ardupilot (the PX4 face "
                             f"takes missions over the mission protocol)")
        server_class = ArduPilotServer if args.autopilot == "ardupilot" else SitlServer
        server = server_class(fleet, geo, bind=args.bind, speed_factor=args.speed_factor,
                              tlog=args.tlog, signing_key=args.signing_key,
                              base_instance=args.instance, pace=args.pace,
                              pace_span_s=args.pace_span, **kwargs)
        if args.defaults is not None:  # (ArduPilot SITL's spelling: FILE[,FILE])
            settings = parm.read_all(args.defaults)
            for agent in server.agents:
                parm.apply(settings, agent.parameters)
        if args.mission is not None:
            items = waypoints.read(args.mission)
            for agent in server.agents:
                agent.mission.load(items)
    except waypoints.WaypointsError as exc:
        raise CliError(f"--mission: {exc}") from None
    except parm.ParmError as exc:
        raise CliError(f"--defaults: {exc}") from None
    except (ValueError, OSError) as exc:
        raise CliError(str(exc)) from None
    urls = server.urls()
    for k, u in enumerate(urls):
        u["instance"] = args.instance + k
        u["ports"] = {"serial": tcp_ports(args.instance + k)} if args.autopilot == \
            "ardupilot" else instance_ports(args.instance + k)
    buses, broker = _sitl_bus(args, server, fleet, scenario)
    for u, b in zip(urls, buses):
        u["mqtt"] = b.pub.url
        u["bus_vehicle"] = b.pub.vehicle

    def announce():  # once the server listens: a script may connect as soon as it reads this
        if args.json:
            out = {"platform": p.name, "vehicles": urls}
            if scenario is not None:
                out["scenario"] = scenario.summary()
                out["spawn_enu"] = spawn
            print(json.dumps(out, indent=2), flush=True)
        else:
            paced = "" if server.pace_span_s is None else \
                f", paced by its clients (at most {server.pace_span_s:g} s ahead)"
            print(f"ft-sitl {__version__}: {args.instances} x {p.name}, speed factor "
                  f"{args.speed_factor:g}{paced}, home {geo.lat_deg:.6f}, {geo.lon_deg:.6f}, "
                  f"{geo.alt_m:.1f} m", flush=True)
            if not loopback:
                print(f"warning: listening on {args.bind}, reachable from other machines",
                      flush=True)
            if wind is not None:
                print("wind: " + ", ".join(f"{k} {v:g}" if isinstance(v, float) else f"{k} {v}"
                                           for k, v in wind.items()), flush=True)
            if actuators is not None:
                print("actuators: " + ", ".join(f"{k} {v:g}" for k, v in actuators.items()),
                      flush=True)
            if estimator is not None:
                print("estimator: " + ", ".join(f"{k} {v}" for k, v in estimator.items()),
                      flush=True)
            for u in urls:
                if args.autopilot == "ardupilot":
                    outs = f"   out {', '.join(u['out'])}" if u["out"] else ""
                    print(f"  vehicle sysid {u['sysid']} (ArduCopter): SERIAL0 {u['serial'][0]}"
                          f"   SERIAL1/2 {', '.join(u['serial'][1:])}{outs}", flush=True)
                    continue
                print(f"  vehicle sysid {u['sysid']}: MAVSDK {u['mavsdk']}   pymavlink "
                      f"{u['pymavlink']}   GCS {u['gcs']}", flush=True)
            if buses:
                where = "embedded broker" if broker is not None else "broker"
                print(f"MQTT bus ({where}) {buses[0].pub.url}: topics ft-sitl/v1/<vehicle>/..., "
                      f"vehicles {', '.join(b.pub.vehicle for b in buses)}", flush=True)
            if scenario is not None:
                o = scenario.takeoff
                print(f"scenario {scenario.name}: {scenario.obstacle_count} obstacles, ceiling "
                      f"{scenario.ceiling:g} m; in vehicle 1's local NED frame (origin = its "
                      f"takeoff point) start {_ned(enu_to_ned(scenario.start - o))}, goal "
                      f"{_ned(enu_to_ned(scenario.goal - o))}, start heading "
                      f"{_heading_deg(scenario.start_yaw):.1f} deg", flush=True)
                if scenario.movers is not None:
                    m = scenario.movers
                    kinds = {}
                    for d in m.describe():
                        kinds[d["shape"]] = kinds.get(d["shape"], 0) + 1
                    shown = ", ".join(f"{n} x {k}" for k, n in kinds.items()) or "none placed"
                    where = "on the bus (topic ft-sitl/v1/<vehicle>/movers) and " if buses \
                        else ""
                    print(f"movers: {m.count} ({shown}), moving from simulated time 0; their "
                          f"state {where}as ADSB_VEHICLE", flush=True)
            print("Ctrl-C stops.", flush=True)

    async def main():
        try:
            await server.start()
        except OSError as exc:  # taken since _check_ports: name the port if it still is
            server.close()
            _check_ports(args)
            raise CliError(f"cannot listen on {args.bind}: {exc.strerror}") from None
        announce()
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
        if args.mission_out is not None:
            waypoints.write(args.mission_out, server.agents[0].mission.mission_items())
            print(f"mission of vehicle 1 written to {args.mission_out}", file=sys.stderr)
    sim_s = fleet.time_us * 1e-6
    behind = (f"; fell {server.behind_s:.1f} s behind the wall clock (stalls are not made "
              "up)" if server.behind_s >= 0.05 else "")
    if server.pace_span_s is not None:
        behind += f"; held {server.held_s:.1f} s waiting for its clients"
    print(f"stopped after {sim_s:.1f} s simulated; achieved speed factor "
          f"{server.achieved_speed_factor:.2f} (asked {args.speed_factor:g}); "
          f"{server.bad_packets} bad packets dropped{behind}", file=sys.stderr)
    return 0

