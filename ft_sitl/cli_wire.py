"""``ft-sitl navigate``: run a registered navigator as an out-of-process MAVSDK client."""

from __future__ import annotations

import asyncio
import json
import math
import sys

import numpy as np


def _cli_error():
    from ft_sitl.cli import CliError

    return CliError


def _vec3(name: str, text: str) -> list[float]:
    parts = [p.strip() for p in str(text).split(",")]
    try:
        v = [float(p) for p in parts]
    except ValueError:
        v = []
    if len(v) != 3 or not all(math.isfinite(x) for x in v):
        raise _cli_error()(f"{name}: {text!r} is not three numbers X,Y,Z")
    return v


def _params(items) -> dict:
    out = {}
    for item in items or []:
        if "=" not in item:
            raise _cli_error()(f"--param: {item!r} is not NAME=VALUE")
        k, v = item.split("=", 1)
        try:
            out[k.strip()] = json.loads(v)
        except json.JSONDecodeError:
            out[k.strip()] = v  # a bare string
    return out


def wire_task_from_args(args):
    """The WireTask of ``ft-sitl navigate``'s arguments."""
    from ft_sitl import frames
    from ft_sitl.wire.navigate import WireTask

    if args.task_json:
        try:
            return WireTask.from_json(args.task_json)
        except ValueError as exc:
            raise _cli_error()(f"--task-json: {exc}") from None
    kw = {"max_speed_m_s": args.max_speed, "timeout_s": args.timeout}
    if args.platform:
        from ft_sitl.cli import _registry

        p = _registry(args).get(args.platform)
        ind = p.indicators()
        kw.update(collision_radius_m=p.collision_radius_m, twr_max=ind.twr_max,
                  alpha_xy_max=ind.alpha_xy_max_rad_s2, alpha_z_max=ind.alpha_z_max_rad_s2)
    if args.scenario:
        from ft_sitl.cli import _sitl_scenario

        sc = _sitl_scenario(args.scenario)
        return WireTask(goal=list(sc.goal), start=list(sc.start), start_yaw=sc.start_yaw,
                        origin=list(sc.takeoff), bounds_min=list(sc.bounds_min),
                        bounds_max=list(sc.bounds_max), **kw)
    if args.goal is None:
        raise _cli_error()("give --goal N,E,D (local NED metres) or --scenario FAMILY:INDEX")
    goal = frames.ned_to_enu(np.array(_vec3("--goal", args.goal)))
    start = frames.ned_to_enu(np.array(_vec3("--start", args.start)))
    if start[2] <= 0.3 or goal[2] <= 0.3:
        raise _cli_error()("--start/--goal: must be above the ground (down < -0.3 m)")
    d = goal - start
    yaw = math.atan2(d[1], d[0]) if args.heading is None else frames.yaw_ned_to_enu(
        math.radians(args.heading))
    lo = np.minimum(start, goal) - 20.0
    hi = np.maximum(start, goal) + 20.0
    return WireTask(goal=list(goal), start=list(start), start_yaw=yaw,
                    bounds_min=[lo[0], lo[1], 0.0], bounds_max=[hi[0], hi[1], hi[2]], **kw)


def cmd_navigate(args) -> int:
    from ft_sitl.navigation.registry import NavigatorError, create
    from ft_sitl.wire.navigate import NavigateError, fly

    if not (0.01 <= args.speed_factor <= 100):
        raise _cli_error()(f"--speed-factor: {args.speed_factor} must be within 0.01..100")
    if args.mqtt:
        from ft_sitl.bus.options import parse_broker_url as parse_url

        try:
            parse_url(args.mqtt)
        except ValueError as exc:
            raise _cli_error()(f"--mqtt: {exc}") from None
    wt = wire_task_from_args(args)
    params = _params(args.param)
    try:
        nav = create(args.algorithm, params)
    except NavigatorError as exc:
        raise _cli_error()(str(exc)) from None
    last = [-1.0]

    def progress(t, obs):
        if not args.quiet and t - last[0] >= 1.0:
            last[0] = t
            d = float(np.linalg.norm(obs.position - np.array(wt.goal)))
            print(f"t {t:6.1f} s  {d:6.1f} m to the goal", file=sys.stderr, flush=True)

    try:
        out = asyncio.run(fly(nav, wt, args.connect, mqtt=args.mqtt, vehicle=args.vehicle,
                              speed_factor=args.speed_factor,
                              connect_timeout_s=args.connect_timeout, progress=progress,
                              real_latency="latency_s" not in params))
    except NavigateError as exc:
        print(f"ft-sitl navigate: {exc}", file=sys.stderr)
        return 3
    except KeyboardInterrupt:
        return 130
    except Exception as exc:  # noqa: BLE001 - the navigator's own failure
        print(f"ft-sitl navigate: navigator error: {type(exc).__name__}: {exc}",
              file=sys.stderr)
        return 3
    print(json.dumps(out) if args.json else f"{out['result']}: {out['detail']}", flush=True)
    return 0 if out["result"] == "success" else 1


def add_parsers(sub) -> None:
    p = sub.add_parser(
        "navigate", help="fly a registered navigator as a MAVSDK client",
        description="Run a registered navigator (ft-sitl navigators list) out of process: "
                    "connect with MAVSDK, take off, reach the start, then stream the "
                    "navigator's setpoints with MAVSDK offboard until the goal is held.")
    p.add_argument("--algorithm", required=True, metavar="NAME", help="navigator name")
    p.add_argument("--param", action="append", metavar="NAME=VALUE",
                   help="navigator parameter (JSON value), repeatable")
    p.add_argument("--connect", default="udpin://0.0.0.0:14540", metavar="URL",
                   help="MAVSDK connection URL (default udpin://0.0.0.0:14540)")
    p.add_argument("--mqtt", metavar="URL", help="the simulator's MQTT bus (telemetry with "
                   "simulated time, depth frames); needed by depth-camera navigators")
    p.add_argument("--vehicle", default="0", help="vehicle id on the bus (default 0)")
    p.add_argument("--scenario", metavar="FAMILY:INDEX[:SEED]|SPEC",
                   help="take start, goal, heading and flight volume from a scenario (as "
                        "served by `ft-sitl sitl --scenario`)")
    p.add_argument("--goal", metavar="N,E,D", help="goal in local NED metres (no --scenario)")
    p.add_argument("--start", default="0,0,-2", metavar="N,E,D",
                   help="start in local NED metres (default 0,0,-2)")
    p.add_argument("--heading", type=float, metavar="DEG",
                   help="start heading (deg, 0 north; default toward the goal)")
    p.add_argument("--platform", metavar="NAME", help="the vehicle's platform (indicators "
                   "and collision radius for the navigator)")
    p.add_argument("--platform-file", action="append", metavar="FILE",
                   help="extra platform definitions")
    p.add_argument("--max-speed", type=float, default=4.0, help="speed cap (default 4 m/s)")
    p.add_argument("--timeout", type=float, default=90.0, help="navigation timeout (s)")
    p.add_argument("--speed-factor", type=float, default=1.0,
                   help="the simulator's speed factor (time base without --mqtt)")
    p.add_argument("--connect-timeout", type=float, default=60.0,
                   help="seconds to wait for the vehicle (default 60)")
    p.add_argument("--task-json", metavar="JSON", help=argparse_suppress())
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    p.set_defaults(func=cmd_navigate)


def argparse_suppress():
    import argparse

    return argparse.SUPPRESS
