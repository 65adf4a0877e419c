"""``ft-sitl bridge px4|ardupilot``: our physics as the simulator of a real autopilot."""

from __future__ import annotations

import math
import signal
import sys


def _cli_error():
    from ft_sitl.cli import CliError

    return CliError


def _speed(v):
    if v is None:
        return None
    if not (math.isfinite(v) and 0.01 <= v <= 100):
        raise _cli_error()(f"--speed-factor: {v} must be within 0.01..100")
    return float(v)


def _stop_on_signals(stoppable) -> None:
    def handler(_sig, _frame):
        stoppable.stop()

    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, handler)


def cmd_bridge_ardupilot(args) -> int:
    from ft_sitl.bridge.ardupilot import FrameMatchError, run_ardupilot_bridge
    from ft_sitl.bridge.ardupilot_params import ardupilot_params
    from ft_sitl.physics.catalog import PlatformRegistry

    platform = PlatformRegistry(args.platform_file or ()).get(args.platform)
    if args.print_params:
        try:
            print(ardupilot_params(platform), end="")
        except FrameMatchError as exc:
            raise _cli_error()(str(exc)) from None
        return 0
    if not 1 <= args.port <= 65535:
        raise _cli_error()(f"--port: {args.port} must be within 1..65535")
    try:
        out = run_ardupilot_bridge(platform, args.scenario, args.port, _speed(args.speed_factor),
                                   host=args.bind, params_path=args.write_params,
                                   on_start=_stop_on_signals)
    except (FrameMatchError, ValueError) as exc:
        raise _cli_error()(str(exc)) from None
    except OSError as exc:
        raise _cli_error()(f"cannot listen on {args.bind}:{args.port}: {exc.strerror}") from None
    print(f"stopped: {out}", file=sys.stderr)
    return 0


def _common(p) -> None:
    """The options both bridges take: the vehicle and its world."""
    p.add_argument("--platform", default="0.98kg-EGO Planner DIY", help="platform name")
    p.add_argument("--platform-file", action="append", metavar="FILE",
                   help="extra platform definitions")
    p.add_argument("--scenario", metavar="FAMILY:INDEX[:SEED]|SPEC",
                   help="fly in a scenario world (collisions crash the vehicle)")
    p.add_argument("--bind", default="127.0.0.1", help="address to listen on")


def add_parsers(sub) -> None:
    from ft_sitl.bridge.ardupilot import DEFAULT_PORT

    br = sub.add_parser("bridge", help="serve our physics to a real PX4 / ArduPilot SITL",
                        description="Autopilot in the loop: a real PX4 or ArduPilot SITL "
                                    "flies our physics, scenarios and sensors "
                                    "(docs/autopilot-in-the-loop.md).")
    bsub = br.add_subparsers(dest="bridge_command", metavar="AUTOPILOT", required=True)
    ap = bsub.add_parser("ardupilot", help="ArduPilot's JSON physics interface (UDP)",
                         description="Serve ArduPilot SITL's JSON interface (--model JSON): "
                                     "one JSON state per servo packet, in lockstep.")
    _common(ap)
    ap.add_argument("--port", type=int, default=DEFAULT_PORT,
                    help=f"UDP port ArduPilot sends to (default {DEFAULT_PORT})")
    ap.add_argument("--speed-factor", type=float, metavar="X",
                    help="pace to X x real time (default: as fast as ArduPilot steps)")
    ap.add_argument("--print-params", action="store_true",
                    help="print the ArduCopter parameter file for the platform and exit")
    ap.add_argument("--write-params", metavar="FILE",
                    help="also write the parameter file to FILE")
    ap.set_defaults(func=cmd_bridge_ardupilot)
    _add_px4(bsub)


def cmd_bridge_px4(args) -> int:
    from ft_sitl.bridge.px4 import BridgeError, run_px4_bridge

    if not 0 <= args.instance <= 999:
        raise _cli_error()(f"--instance: {args.instance} must be within 0..999")
    if args.duration is not None and not args.duration > 0:
        raise _cli_error()(f"--duration: {args.duration} must be positive")
    try:
        run_px4_bridge(args.platform, args.scenario, instance=args.instance,
                       speed_factor=_speed(args.speed_factor), ground_truth=args.ground_truth,
                       host=args.bind, platform_files=args.platform_file or (),
                       duration_s=args.duration)
    except (ValueError, BridgeError) as exc:
        raise _cli_error()(str(exc)) from None
    return 0


def _add_px4(bsub) -> None:
    px = bsub.add_parser("px4", help="PX4's simulator_mavlink interface (HIL over TCP)",
                         description="Listen on TCP 4560+I for a PX4 SITL (px4_sitl_default, "
                                     "airframe none_iris) and fly our physics in lockstep: "
                                     "HIL_SENSOR / HIL_GPS out, HIL_ACTUATOR_CONTROLS in.")
    _common(px)
    px.add_argument("--instance", type=int, default=0, metavar="I",
                    help="PX4 instance (px4 -i I): TCP port 4560+I (default 0)")
    px.add_argument("--speed-factor", type=float, metavar="X",
                    help="pace to X x real time (default: as fast as PX4 steps)")
    px.add_argument("--ground-truth", action="store_true",
                    help="also send HIL_STATE_QUATERNION (ground truth)")
    px.add_argument("--duration", type=float, metavar="S", help="stop after S wall seconds")
    px.set_defaults(func=cmd_bridge_px4)
