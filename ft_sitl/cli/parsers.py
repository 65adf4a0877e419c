"""The ``ft-sitl`` argument parser: every command's options, nothing that runs them.

Each command names its handler as ``"MODULE:FUNCTION"`` (``set_defaults(handler=...)``), a
module of :mod:`ft_sitl.cli`; :func:`ft_sitl.cli.main` imports that module only when the
command runs, so building the parser (``ft-sitl --help``) loads no simulator, planner,
mesh or plotting code.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from ft_sitl import __version__, numeric_env
from ft_sitl.bridge import ARDUPILOT_DEFAULT_PORT
from ft_sitl.cli.common import CliError, number
from ft_sitl.mavlink.autopilots import AUTOPILOTS, DEFAULT_AUTOPILOT
from ft_sitl.navigation.base import LIMITS  # numpy and the setpoint type: cheap too
from ft_sitl.physics.platform import CATEGORIES  # loaded by cli.common anyway
from ft_sitl.scenarios.render import DEFAULT_DPI  # numpy only: cheap at start-up

ACTUATORS_HELP = ("imperfect actuators as KEY=VALUE,... (efficiency, degraded_motor, "
                  "degraded_efficiency, lag_s, noise, fail_motor, fail_at_s, stuck_motor, "
                  "stuck_at_s; "
                  "docs/platforms.md, Actuator imperfection)")


class _Version(argparse.Action):
    """``--version``: ft-sitl's version and the instruction-set level its numeric
    libraries compute at here (ft_sitl.numeric_env), which rows made here record."""

    def __call__(self, parser, namespace, values, option_string=None):
        f = numeric_env.in_force()
        print(f"ft-sitl {__version__}\n"
              f"numeric libraries at {f['level']} on {f['cpu']} (numba {f['numba_cpu']}, "
              f"numpy up to {f['numpy_dispatch']}, OpenBLAS {f['openblas']}, Embree "
              f"{f['embree']}; FT_SITL_ISA)")
        parser.exit()


_INSTANCE = number("--instance", minimum=0, maximum=999, integer=True)


def _instance_number(text: str):
    """``--instance``: a number 0..999, or ``auto`` (a free one, chosen when serving)."""
    if text == "auto":
        return text
    try:
        int(text)
    except ValueError:
        raise CliError(f"--instance: {text!r} is neither an integer nor auto") from None
    return _INSTANCE(text)


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(
        prog="ft-sitl",
        description="FLYINGTRUST quadrotor SITL: platforms, rotor dynamics and a virtual PX4.",
    )
    ap.add_argument("--version", action=_Version, nargs=0,
                    help="show the version and the arithmetic in force, and exit")
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
    demo.set_defaults(handler="demo:cmd_demo")

    plat = sub.add_parser("platforms", help="the platform catalog",
                          description="List, show, check and generate platforms, and make "
                          "controlled series.")
    psub = plat.add_subparsers(dest="platforms_command", metavar="ACTION", required=True)
    pl = psub.add_parser("list", parents=[pf], help="list platforms with their indicators")
    pl.add_argument("--category", choices=CATEGORIES)
    pl.add_argument("--json", action="store_true", help="machine-readable output")
    pl.set_defaults(handler="platforms:cmd_platforms_list")
    ps = psub.add_parser("show", parents=[pf], help="show one platform's physical parameters")
    ps.add_argument("name")
    ps.add_argument("--json", action="store_true", help="machine-readable output")
    ps.set_defaults(handler="platforms:cmd_platforms_show")
    pc = psub.add_parser("check", help="validate a user platform file")
    pc.add_argument("file", type=Path)
    pc.add_argument("--json", action="store_true", help="machine-readable output")
    pc.set_defaults(handler="platforms:cmd_platforms_check")
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
    pg.set_defaults(handler="platforms:cmd_platforms_generate")
    pse = psub.add_parser(
        "series", parents=[pf], help="one platform's body with one indicator changed",
        description="A controlled series of BASE (a catalog or --platform-file platform): "
        "the same body, mass and geometry with TWR_max changed by its motors (alpha held by "
        "the inertia), or alpha_xy,max changed by its mass distribution (TWR_max held). "
        "Prints a TOML platform file (physical form, category user); docs/platforms.md, "
        "Controlled platform series.")
    pse.add_argument("base", help="the platform whose body the series keeps")
    pse.add_argument("--twr", type=number("--twr"), nargs="+", default=[], metavar="TWR",
                     help="TWR_max of the TWR series' members")
    pse.add_argument("--alpha-xy", type=number("--alpha-xy"), nargs="+", default=[],
                     metavar="RAD_S2", help="alpha_xy,max (rad/s^2) of the alpha series' "
                     "members")
    pse.add_argument("--out", type=Path, help="write the TOML platform file here")
    pse.add_argument("--force", action="store_true", help="overwrite --out if it exists")
    pse.add_argument("--json", action="store_true", help="print the members' indicators "
                     "as JSON")
    pse.set_defaults(handler="platforms:cmd_platforms_series")

    sitl = sub.add_parser(
        "sitl", parents=[pf], help="serve vehicles over MAVLink like PX4 SITL",
        description="Start N simulated vehicles with PX4 SITL's UDP ports: vehicle i (sysid "
        "i+1) sends to 127.0.0.1:14540+i (MAVSDK, listens on 14580+i) and to "
        "127.0.0.1:14550 (GCS, listens on 18570+i).")
    sitl.add_argument("--platform", default="0.98kg-EGO Planner DIY",
                      help="platform name (default: %(default)s)")
    sitl.add_argument("--instances", type=number("--instances", minimum=1, maximum=64,
                                                  integer=True),
                      default=1, help="number of vehicles (1..64)")
    sitl.add_argument("--mqtt", metavar="URL", help="MQTT broker for the bus "
                      "(mqtt://[user[:pass]@]host[:port] or mqtts://...; default: an "
                      "embedded broker on a free port)")
    sitl.add_argument("--mqtt-ca", metavar="FILE", help="CA bundle for mqtts://")
    sitl.add_argument("--mqtt-cert", metavar="FILE", help="client certificate for mqtts://")
    sitl.add_argument("--mqtt-key", metavar="FILE", help="client key for mqtts://")
    sitl.add_argument("--mqtt-insecure", action="store_true",
                      help="do not verify the broker's certificate (testing only)")
    sitl.add_argument("--no-mqtt", action="store_true", help="no MQTT bus")
    sitl.add_argument("--telemetry-rate", type=number("--telemetry-rate", minimum=1,
                                                      maximum=1000),
                      default=50.0, metavar="HZ",
                      help="bus telemetry rate in simulated Hz, 1..1000 (default 50)")
    sitl.add_argument("--camera", choices=("benchmark", "d435", "none"), default="benchmark",
                      help="depth camera for bus depth frames with --scenario (default "
                           "benchmark: 160 x 120 @ 15 Hz)")
    sitl.add_argument("--instance", type=_instance_number, default=0, metavar="I|auto",
                      help="first instance number, as PX4's -i: ports 14580+I, 14540+I, "
                           "18570+I (default 0; I + instances <= 1000); auto: the lowest "
                           "free run of numbers in 20..39, 80..99 whose ports are free "
                           "(--json says which)")
    sitl.add_argument("--autopilot", choices=AUTOPILOTS, default=DEFAULT_AUTOPILOT,
                      help="the face on the wire: px4 (PX4 SITL's UDP ports, default) or "
                           "ardupilot (ArduCopter: TCP 5760+10*I for SERIAL0, 5762+10*I and "
                           "5763+10*I, ArduCopter's modes and parameters; docs/mavlink.md)")
    sitl.add_argument("--out", action="append", default=[], metavar="udp:HOST:PORT",
                      help="with --autopilot ardupilot: also send to (and answer) this UDP "
                           "target, as MAVProxy's --out (repeatable)")
    sitl.add_argument("--mission", type=Path, metavar="FILE",
                      help="with --autopilot ardupilot: load this QGC WPL 110 .waypoints "
                           "file into every vehicle at start, as an upload (item 0 home)")
    sitl.add_argument("--defaults", metavar="FILE[,FILE]",
                      help="with --autopilot ardupilot: set the parameters of these .parm "
                           "files (NAME VALUE or NAME,VALUE lines, # comments; later files "
                           "win) in every vehicle at start, as ArduPilot SITL's --defaults; "
                           "an unknown name or out-of-range value is refused")
    sitl.add_argument("--mission-out", type=Path, metavar="FILE",
                      help="with --autopilot ardupilot: on stopping, write vehicle 1's "
                           "mission (as a download reads it, home at 0) as QGC WPL 110")
    sitl.add_argument("--speed-factor", type=number("--speed-factor", minimum=0.01,
                                                    maximum=1000),
                      default=1.0,
                      help="simulated seconds per wall second, 0.01..1000 (default: 1)")
    sitl.add_argument("--pace", choices=("wall", "client"), default="wall",
                      help="wall: the simulated clock runs at the speed factor whatever the "
                           "clients do (default); client: also never more than --pace-span "
                           "past the last MAVLink message from a client (a starved client "
                           "sees a slower world, not a different one)")
    sitl.add_argument("--pace-span", type=number("--pace-span"), metavar="S",
                      help="with --pace client: simulated seconds the clock may run past the "
                           "client's last message, 0.004..60 (default 0.05)")
    sitl.add_argument("--home", metavar="LAT,LON,ALT",
                      help="geodetic home (default: PX4 SITL's 47.397742,8.545594,488)")
    sitl.add_argument("--bind", default="127.0.0.1",
                      help="address to listen on (default: loopback only)")
    sitl.add_argument("--tlog", type=Path, metavar="PATH",
                      help="record all MAVLink traffic as a telemetry log")
    sitl.add_argument("--signing-key", metavar="KEY",
                      help="MAVLink 2 signing passphrase: unsigned packets are rejected")
    sitl.add_argument("--duration", type=number("--duration", above=0), metavar="S",
                      help="stop after S wall seconds, S > 0 (default: run until Ctrl-C)")
    sitl.add_argument("--scenario", metavar="FAMILY:INDEX[:SEED]|SPEC",
                      help="fly in a scenario world (e.g. forest:3, or a .yaml/.toml spec; "
                           "+dynamic(count=8,speed=1.5) adds moving obstacles): spawn at its "
                           "takeoff point, crash on collision")
    sitl.add_argument("--json", action="store_true", help="print the vehicle URLs as JSON")
    sitl.add_argument("--wind", metavar="SETTINGS",
                      help="wind as KEY=VALUE,... (speed_m_s, from_deg, vertical_m_s, "
                         "turbulence none|light|moderate|severe|standard, gust_m_s, ...; "
                         "docs/platforms.md, Wind)")
    sitl.add_argument("--wind-seed", type=number("--wind-seed", minimum=0, integer=True),
                      default=0, metavar="N",
                      help="turbulence and estimator-noise seed (vehicle i uses N + i; "
                           "default 0)")
    sitl.add_argument("--estimator", metavar="SETTINGS",
                      help="the flight controller flies on (and reports) an imperfect "
                           "estimate: KEY=VALUE,... (position_noise_m, position_bias_m=E:N:U, "
                           "position_latency_s, velocity_*, attitude_*_deg, rate_*_deg_s, "
                           "noise_correlation_s; docs/control.md, Estimator)")
    sitl.add_argument("--actuators", metavar="SETTINGS",
                      help=ACTUATORS_HELP)
    sitl.set_defaults(handler="sitl:cmd_sitl")

    par = sub.add_parser("params", help="flight-controller parameters")
    parsub = par.add_subparsers(dest="params_command", metavar="ACTION", required=True)
    parl = parsub.add_parser("list", help="list PX4-named parameters with defaults and bounds",
                             description="Every parameter the flight controller serves: "
                             "honoured (ft-sitl acts on it) or stored (accepted, remembered "
                             "and echoed over MAVLink, no effect on the flight).")
    parl.add_argument("--json", action="store_true", help="machine-readable output")
    which = parl.add_mutually_exclusive_group()
    which.add_argument("--honoured", action="store_true",
                       help="only the parameters ft-sitl acts on")
    which.add_argument("--stored", action="store_true",
                       help="only the parameters that are merely stored")
    parl.set_defaults(handler="params:cmd_params_list")
    pars = parsub.add_parser("show", help="one parameter: type, default, range, meaning and "
                             "how it compares with PX4's")
    pars.add_argument("name", help="parameter name (ft-sitl params list)")
    pars.add_argument("--json", action="store_true", help="machine-readable output")
    pars.set_defaults(handler="params:cmd_params_show")

    _add_missions(sub)
    _add_navigators(sub)
    _add_navigate(sub)
    _add_bridge(sub)
    _add_scenarios(sub)
    _add_train(sub)
    return ap


def _add_train(sub) -> None:
    t = sub.add_parser(
        "train", help="train a navigation policy with PPO (needs the 'train' extra)",
        description="Train a velocity policy on the batched Gymnasium environment with "
                    "Stable-Baselines3's PPO on the CPU and write it as a policy file the "
                    "'learned' navigator flies (params.policy = PATH). The configuration is "
                    "a TOML file with [train], [env] and [reward] tables (default: the "
                    "shipped policy's, ft_sitl/gym/presets/learned.toml; docs/gym.md, "
                    "\"Training\"). Writes OUT/config.json, training.csv, training.png and "
                    "policy.npz.")
    t.add_argument("--config", metavar="FILE", help="training configuration (TOML)")
    t.add_argument("--out", metavar="DIR", required=True, help="output directory")
    t.add_argument("--steps", type=number("--steps", minimum=1, integer=True), metavar="N",
                   help="environment steps (overrides [train] total_steps)")
    t.add_argument("--seed", type=number("--seed", minimum=0, maximum=2**31 - 1, integer=True),
                   metavar="S",
                   help="seed (overrides [train] seed)")
    t.add_argument("--check", action="store_true",
                   help="check the configuration and print it; train nothing")
    t.add_argument("--quiet", action="store_true", help="no progress bar")
    t.set_defaults(handler="train:cmd_train")


def _add_missions(sub) -> None:
    camp = sub.add_parser("campaign", help="run benchmark campaigns and report them",
                          description="Run the FLYINGTRUST matrix (algorithms x platforms x "
                                      "scenarios x trials) and report it.")
    csub = camp.add_subparsers(dest="campaign_command", metavar="ACTION", required=True)
    cr = csub.add_parser("run", help="run (or resume) a campaign",
                         description="Run a campaign file or preset (quick, paper, gains) into "
                                     "--out; rerunning the same command resumes it.")
    cr.add_argument("campaign", help="campaign file (.toml, .yaml) or preset: quick, paper, gains")
    cr.add_argument("--out", required=True, metavar="DIR", help="result directory")
    cr.add_argument("--workers", type=int, default=1,
                    help="worker processes on this machine (default 1), or with --cluster "
                         "local the Dask workers to start")
    cr.add_argument("--scheduler", metavar="ADDRESS",
                    help="fly the trials on an existing Dask cluster, e.g. "
                         "tcp://host:8786 (docs/distributed.md)")
    cr.add_argument("--cluster", choices=("local",),
                    help="local: start a Dask LocalCluster of --workers processes here")
    cr.add_argument("--chunk-size", type=int, metavar="N",
                    help="trials per Dask task (default 10; same scenario configuration)")
    cr.add_argument("--csv", action="store_true", help="also write trials.csv")
    cr.add_argument("--no-report", action="store_true", help="do not write the report")
    cr.add_argument("--limit", type=int, metavar="N", help="stop after N new trials")
    cr.add_argument("--reuse", action="append", metavar="DIR",
                    help="take the rows of this campaign's trials that the result directory "
                         "DIR already holds (the same trial id: the same spec) instead of "
                         "flying them again, e.g. from a campaign that differs only in "
                         "some trials; repeatable")
    cr.add_argument("--quiet", action="store_true", help="no progress bar")
    cr.add_argument("--transport", choices=("inprocess", "mavlink"), default="inprocess",
                    help="inprocess (default): navigators called in lockstep; mavlink: each "
                         "trial's vehicle served over MAVLink and its navigator run as a "
                         "MAVSDK client process (docs/wire.md)")
    cr.add_argument("--speed-factor", type=float, default=2.0,
                    help="simulated/wall time over MAVLink when free-running (default 2)")
    cr.add_argument("--free-running", action="store_true",
                    help="over MAVLink, pace the simulator against the wall clock at "
                         "--speed-factor and let the navigator run on its own (for latency "
                         "studies); default: lockstep, rows equal to in-process ones "
                         "(protocol 10 on; docs/wire.md, Lockstep)")
    cr.add_argument("--mqtt", metavar="URL", help="MQTT broker for the bus over MAVLink "
                    "(default: an embedded broker per worker)")
    cr.add_argument("--autopilot", choices=AUTOPILOTS, default=DEFAULT_AUTOPILOT,
                    help="over MAVLink, the face that serves each trial's vehicle, as ft-sitl "
                         "sitl --autopilot: px4 (default; the navigator flies offboard) or "
                         "ardupilot (ArduCopter; the navigator flies GUIDED); the vehicle "
                         "keeps the trial's parameters either way (docs/wire.md, Autopilots)")
    cr.set_defaults(handler="missions:cmd_campaign_run")
    cc = csub.add_parser("check", help="validate a campaign and show its matrix")
    cc.add_argument("campaign", help="campaign file (.toml, .yaml) or preset: quick, paper, gains")
    cc.add_argument("--json", action="store_true", help="machine-readable output")
    cc.set_defaults(handler="missions:cmd_campaign_check")
    crep = csub.add_parser("report", help="write the HTML/Markdown report of a result dir")
    crep.add_argument("dir", help="campaign result directory")
    crep.add_argument("--csv", action="store_true", help="also write trials.csv")
    crep.set_defaults(handler="missions:cmd_campaign_report")

    ccmp = csub.add_parser("compare", help="outcome agreement of two result dirs",
                           description="Compare two result directories trial by trial (the "
                                       "same campaign in-process and --transport mavlink, "
                                       "or two code versions): how often success and the "
                                       "reason agree, and which trials differ.")
    ccmp.add_argument("a", help="result directory A")
    ccmp.add_argument("b", help="result directory B")
    ccmp.add_argument("--json", action="store_true", help="machine-readable output")
    ccmp.set_defaults(handler="missions:cmd_campaign_compare")

    tr = sub.add_parser("trial", help="single trials")
    tsub = tr.add_subparsers(dest="trial_command", metavar="ACTION", required=True)
    trr = tsub.add_parser("rerun", help="replay one trial of a campaign and compare",
                          description="Replay one trial from its stored spec and check that "
                                      "it gives the same result.")
    trr.add_argument("dir", nargs="?", help="result directory (a campaign's, or one "
                     "holding only trials.parquet)")
    trr.add_argument("trial_id", nargs="?", help="trial id (a unique prefix is enough)")
    trr.add_argument("--spec", metavar="FILE", help="a trial spec JSON file instead")
    trr.add_argument("--trajectory", metavar="CSV", help="save the flown trajectory")
    trr.add_argument("--render", metavar="PNG", help="draw the trajectory over the scenario")
    trr.add_argument("--sample", type=int, metavar="N",
                     help="rerun N trials of the directory, stratified over (algorithm, "
                          "family), instead of one trial id")
    trr.add_argument("--sample-seed", type=int, default=0, metavar="S",
                     help="which trials --sample picks (default 0)")
    trr.set_defaults(handler="missions:cmd_trial_rerun")


def _add_navigators(sub) -> None:
    nav = sub.add_parser("navigators", help="the registered navigation algorithms")
    nsub = nav.add_subparsers(dest="navigators_command", metavar="ACTION", required=True)
    nl = nsub.add_parser("list", help="list navigators and their parameters")
    nl.add_argument("--json", action="store_true", help="machine-readable output")
    nl.set_defaults(handler="navigators:cmd_navigators_list")
    ns = nsub.add_parser("show", help="one navigator's parameters: default, unit, range, "
                                      "meaning")
    ns.add_argument("name", help="navigator name (ft-sitl navigators list)")
    ns.add_argument("--json", action="store_true", help="machine-readable output")
    ns.set_defaults(handler="navigators:cmd_navigators_show")
    ni = nsub.add_parser("install", help="install a navigator's model weights (navrl)",
                         description="Check a NavRL policy checkpoint (the authors' released "
                                     "navrl_checkpoint.pt) and copy it to the data directory "
                                     "where the navrl navigator finds it.")
    ni.add_argument("name", help="navigator (navrl)")
    ni.add_argument("path", help="checkpoint file")
    ni.set_defaults(handler="navigators:cmd_navigators_install")


def _add_navigate(sub) -> None:
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
    p.add_argument("--heading", type=number("--heading"), metavar="DEG",
                   help="start heading (deg, 0 north; default toward the goal)")
    p.add_argument("--platform", metavar="NAME", help="the vehicle's platform (indicators "
                   "and collision radius for the navigator)")
    p.add_argument("--platform-file", action="append", metavar="FILE",
                   help="extra platform definitions")
    speed, timeout = LIMITS["max_speed_m_s"], LIMITS["timeout_s"]
    p.add_argument("--max-speed", type=number("--max-speed", minimum=speed.range[0],
                                              maximum=speed.range[1]),
                   default=speed.default, help=f"{speed.doc} ({speed.allowed()} {speed.unit}; "
                   f"default {speed.default:g})")
    p.add_argument("--timeout", type=number("--timeout", minimum=timeout.range[0],
                                            maximum=timeout.range[1]),
                   default=timeout.default, help=f"{timeout.doc} ({timeout.allowed()} "
                   f"{timeout.unit}; default {timeout.default:g})")
    p.add_argument("--speed-factor", type=number("--speed-factor", minimum=0.01, maximum=100),
                   default=1.0, help="the simulator's speed factor, 0.01..100 (time base "
                   "without --mqtt; default 1)")
    p.add_argument("--connect-timeout", type=number("--connect-timeout", above=0),
                   default=60.0, help="seconds to wait for the vehicle (default 60)")
    p.add_argument("--task-json", metavar="JSON", help=argparse.SUPPRESS)
    p.add_argument("--lockstep", action="store_true",
                   help="answer a lockstep trial's ticks (the simulator flies the approach and "
                        "holds its clock at every tick until the setpoint has arrived; needs "
                        "--mqtt; docs/wire.md, Lockstep)")
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    p.set_defaults(handler="navigate:cmd_navigate")


def _bridge_options(p) -> None:
    """The options both bridges take: the vehicle and its world."""
    p.add_argument("--platform", default="0.98kg-EGO Planner DIY", help="platform name")
    p.add_argument("--platform-file", action="append", metavar="FILE",
                   help="extra platform definitions")
    p.add_argument("--scenario", metavar="FAMILY:INDEX[:SEED]|SPEC",
                   help="fly in a scenario world (collisions crash the vehicle; "
                        "+dynamic(...) adds moving obstacles)")
    p.add_argument("--bind", default="127.0.0.1", help="address to listen on")
    p.add_argument("--wind", metavar="SETTINGS",
                   help="wind as KEY=VALUE,... (speed_m_s, from_deg, vertical_m_s, "
                      "turbulence none|light|moderate|severe|standard, gust_m_s, ...; "
                      "docs/platforms.md, Wind)")
    p.add_argument("--actuators", metavar="SETTINGS", help=ACTUATORS_HELP)
    p.add_argument("--spawn-yaw", type=number("--spawn-yaw", minimum=-360, maximum=360),
                   metavar="DEG", help="heading the vehicle spawns with, degrees clockwise "
                   "from north (default: north, or the scenario's start heading)")


def _add_bridge(sub) -> None:
    br = sub.add_parser("bridge", help="serve our physics to a real PX4 / ArduPilot SITL",
                        description="Autopilot in the loop: a real PX4 or ArduPilot SITL "
                                    "flies our physics, scenarios and sensors "
                                    "(docs/autopilot-in-the-loop.md).")
    bsub = br.add_subparsers(dest="bridge_command", metavar="AUTOPILOT", required=True)
    ap = bsub.add_parser("ardupilot", help="ArduPilot's JSON physics interface (UDP)",
                         description="Serve ArduPilot SITL's JSON interface (--model JSON): "
                                     "one JSON state per servo packet, in lockstep.")
    _bridge_options(ap)
    ap.add_argument("--port", type=number("--port", minimum=1, maximum=65535, integer=True),
                    default=ARDUPILOT_DEFAULT_PORT,
                    help=f"UDP port ArduPilot sends to (default {ARDUPILOT_DEFAULT_PORT})")
    ap.add_argument("--speed-factor", type=number("--speed-factor", minimum=0.01, maximum=100),
                    metavar="X", help="pace to X x real time, 0.01..100 (default: as fast as "
                    "ArduPilot steps)")
    ap.add_argument("--print-params", action="store_true",
                    help="print the ArduCopter parameter file for the platform and exit")
    ap.add_argument("--write-params", metavar="FILE",
                    help="also write the parameter file to FILE")
    ap.set_defaults(handler="bridge:cmd_bridge_ardupilot")
    _add_px4(bsub)


def _add_px4(bsub) -> None:
    px = bsub.add_parser("px4", help="PX4's simulator_mavlink interface (HIL over TCP)",
                         description="Listen on TCP 4560+I for a PX4 SITL (px4_sitl_default, "
                                     "airframe none_iris) and fly our physics in lockstep: "
                                     "HIL_SENSOR / HIL_GPS out, HIL_ACTUATOR_CONTROLS in.")
    _bridge_options(px)
    px.add_argument("--instance", type=number("--instance", minimum=0, maximum=999,
                                               integer=True),
                    default=0, metavar="I",
                    help="PX4 instance (px4 -i I), 0..999: TCP port 4560+I (default 0)")
    px.add_argument("--speed-factor", type=number("--speed-factor", minimum=0.01, maximum=100),
                    metavar="X", help="pace to X x real time, 0.01..100 (default: as fast as "
                    "PX4 steps)")
    px.add_argument("--ground-truth", action="store_true",
                    help="also send HIL_STATE_QUATERNION (ground truth)")
    px.add_argument("--duration", type=number("--duration", above=0), metavar="S",
                    help="stop after S wall seconds, S > 0")
    px.set_defaults(handler="bridge:cmd_bridge_px4")


def _add_scenarios(sub) -> None:
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

    diff = argparse.ArgumentParser(add_help=False)
    diff.add_argument("--difficulty", action="store_true",
                      help="measure the difficulty for the largest platform's body: "
                      "shortest path, narrowest passage, turns, obstacles, flight time "
                      "(cached; docs/scenarios.md, 'Difficulty')")
    diff.add_argument("--no-cache", action="store_true",
                      help="with --difficulty: measure again, ignoring and not writing the "
                      "cache")
    diff_seed = argparse.ArgumentParser(add_help=False)
    diff_seed.add_argument("--seed", type=int,
                           help="with --difficulty: the configurations of this seed, >= 0 "
                           "(default: 0)")

    sl = ssub.add_parser("list", parents=[diff, diff_seed], help="list the scenario families",
                         description="List the scenario families; --difficulty measures "
                         "all 70 configurations (minutes the first time, then cached).")
    sl.add_argument("--json", action="store_true", help="machine-readable output")
    sl.set_defaults(handler="scenarios:cmd_scenarios_list")
    ssh = ssub.add_parser("show", parents=[diff, diff_seed],
                          help="one family's generator parameters: default, unit, range, "
                          "meaning", description="One family's generator parameters; "
                          "--difficulty measures its 10 configurations.")
    ssh.add_argument("family", metavar="FAMILY",
                     help="family name, e.g. forest or the paper's Narrow-Gap")
    ssh.add_argument("--json", action="store_true", help="machine-readable output")
    ssh.set_defaults(handler="scenarios:cmd_scenarios_show")
    sb = ssub.add_parser("build", parents=[src, diff],
                         help="build one scenario and summarise it",
                         description="Build a scenario and print its summary.")
    sb.add_argument("--json", action="store_true", help="print Scenario.summary() as JSON")
    sb.set_defaults(handler="scenarios:cmd_scenarios_build")
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
    se.set_defaults(handler="scenarios:cmd_scenarios_export")
    sr = ssub.add_parser("render", parents=[src], help="draw a scenario to a PNG",
                         description="Draw a top view and a perspective view of a scenario "
                         "(start, goal, straight line, optional trajectory) to a PNG.")
    sr.add_argument("-o", "--out", type=Path, metavar="PNG",
                    help="output picture (default: <scenario name>.png here)")
    sr.add_argument("--trajectory", type=Path, metavar="FILE",
                    help="draw a flown path: .csv (x,y,z columns) or .npy (N x 3), ENU m")
    sr.add_argument("--dpi", type=float, default=DEFAULT_DPI,
                    help="resolution, dots per inch (default: %(default)s)")
    sr.set_defaults(handler="scenarios:cmd_scenarios_render")
