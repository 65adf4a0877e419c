"""``ft-sitl bridge px4|ardupilot``: our physics as the simulator of a real autopilot."""

from __future__ import annotations

import signal
import sys

from ft_sitl.bridge.ardupilot import run_ardupilot_bridge
from ft_sitl.bridge.ardupilot_frames import FrameMatchError
from ft_sitl.bridge.ardupilot_params import ardupilot_params
from ft_sitl.bridge.px4 import BridgeError, run_px4_bridge
from ft_sitl.cli.common import CliError, actuators_option, platform_registry, wind_option


def _stop_on_signals(stoppable) -> None:
    def handler(_sig, _frame):
        stoppable.stop()

    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, handler)


def cmd_bridge_ardupilot(args) -> int:
    platform = platform_registry(args).get(args.platform)
    if args.print_params:
        try:
            print(ardupilot_params(platform), end="")
        except FrameMatchError as exc:
            raise CliError(str(exc)) from None
        return 0
    try:
        out = run_ardupilot_bridge(platform, args.scenario, args.port, args.speed_factor,
                                   host=args.bind, params_path=args.write_params,
                                   on_start=_stop_on_signals, wind=wind_option(args.wind),
                                   actuators=actuators_option(args.actuators),
                                   spawn_heading_deg=args.spawn_yaw)
    except (FrameMatchError, ValueError) as exc:
        raise CliError(str(exc)) from None
    except OSError as exc:
        raise CliError(f"cannot listen on {args.bind}:{args.port}: {exc.strerror}") from None
    print(f"stopped: {out}", file=sys.stderr)
    return 0


def cmd_bridge_px4(args) -> int:
    # --instance, --speed-factor, --duration: checked as parsed (cli.common.number)
    try:
        run_px4_bridge(args.platform, args.scenario, instance=args.instance,
                       speed_factor=args.speed_factor, ground_truth=args.ground_truth,
                       host=args.bind, platform_files=args.platform_file or (),
                       duration_s=args.duration, wind=wind_option(args.wind),
                       actuators=actuators_option(args.actuators),
                       spawn_heading_deg=args.spawn_yaw)
    except (ValueError, BridgeError) as exc:
        raise CliError(str(exc)) from None
    return 0
