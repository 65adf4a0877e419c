"""``ft-sitl demo``: a short demo flight, reported phase by phase."""

from __future__ import annotations

import json

from ft_sitl import __version__
from ft_sitl.cli.common import CliError, platform_registry
from ft_sitl.demo import plot_demo, run_demo


def cmd_demo(args) -> int:
    p = platform_registry(args).get(args.platform)
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

