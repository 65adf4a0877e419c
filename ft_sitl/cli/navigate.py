"""``ft-sitl navigate``: run a registered navigator as an out-of-process MAVSDK client."""

from __future__ import annotations

import asyncio
import json
import math
import sys

import numpy as np

from ft_sitl import frames
from ft_sitl.bus.options import parse_broker_url
from ft_sitl.cli.common import CliError, option_value, platform_registry
from ft_sitl.navigation.base import Task, TaskError
from ft_sitl.navigation.registry import NavigatorError, create
from ft_sitl.scenarios.io import scenario_from_spec
from ft_sitl.wire.navigate import (
    ClientResult,
    NavigateError,
    fly,
    fly_lockstep,
    require_mavsdk,
    task_from_json,
)


def _vec3(name: str, text: str) -> list[float]:
    parts = [p.strip() for p in str(text).split(",")]
    try:
        v = [float(p) for p in parts]
    except ValueError:
        v = []
    if len(v) != 3 or not all(math.isfinite(x) for x in v):
        raise CliError(f"{name}: {text!r} is not three numbers X,Y,Z")
    return v


def _params(items) -> dict:
    out = {}
    for item in items or []:
        if "=" not in item:
            raise CliError(f"--param: {item!r} is not NAME=VALUE")
        k, v = item.split("=", 1)
        try:
            out[k.strip()] = json.loads(v)
        except json.JSONDecodeError:
            out[k.strip()] = v  # a bare string
    return out


def task_from_args(args) -> Task:
    """The Task of ``ft-sitl navigate``'s arguments: ``--task-json`` whole, else built from
    a scenario or a goal and a start, the limits and the platform given."""
    if args.task_json:
        try:
            return task_from_json(args.task_json)
        except TaskError as exc:
            raise CliError(f"--task-json: {exc}") from None
    doc: dict = {"max_speed_m_s": args.max_speed, "timeout_s": args.timeout}
    if args.platform:
        p = platform_registry(args).get(args.platform)
        ind = p.indicators()
        doc.update(collision_radius_m=p.collision_radius_m, twr_max=ind.twr_max,
                   alpha_xy_max=ind.alpha_xy_max_rad_s2, alpha_z_max=ind.alpha_z_max_rad_s2)
    if args.scenario:
        sc = option_value("--scenario", scenario_from_spec, args.scenario)
        doc.update(goal=list(sc.goal), start=list(sc.start), start_yaw=float(sc.start_yaw),
                   origin=list(sc.takeoff), bounds_min=list(sc.bounds_min),
                   bounds_max=list(sc.bounds_max))
    else:
        if args.goal is None:
            raise CliError("give --goal N,E,D (local NED metres) or --scenario FAMILY:INDEX")
        goal = frames.ned_to_enu(np.array(_vec3("--goal", args.goal)))
        start = frames.ned_to_enu(np.array(_vec3("--start", args.start)))
        if start[2] <= 0.3 or goal[2] <= 0.3:
            raise CliError("--start/--goal: must be above the ground (down < -0.3 m)")
        d = goal - start
        yaw = math.atan2(d[1], d[0]) if args.heading is None else frames.yaw_ned_to_enu(
            math.radians(args.heading))
        lo = np.minimum(start, goal) - 20.0
        hi = np.maximum(start, goal) + 20.0
        doc.update(goal=goal.tolist(), start=start.tolist(), start_yaw=float(yaw),
                   bounds_min=[float(lo[0]), float(lo[1]), 0.0], bounds_max=hi.tolist())
    try:
        return Task.from_dict(doc)
    except TaskError as exc:
        raise CliError(str(exc)) from None


def cmd_navigate(args) -> int:
    try:
        require_mavsdk()
    except NavigateError as exc:
        raise CliError(str(exc)) from None
    if args.mqtt:
        option_value("--mqtt", parse_broker_url, args.mqtt)
    task = task_from_args(args)
    params = _params(args.param)
    try:
        nav = create(args.algorithm, params)
    except NavigatorError as exc:
        raise CliError(str(exc)) from None
    last = [-1.0]

    def progress(t, obs):
        if not args.quiet and t - last[0] >= 1.0:
            last[0] = t
            d = float(np.linalg.norm(obs.position - task.goal))
            print(f"t {t:6.1f} s  {d:6.1f} m to the goal", file=sys.stderr, flush=True)

    if args.lockstep and not args.mqtt:
        raise CliError("--lockstep: needs --mqtt URL (the ticks come on the simulator's bus)")
    try:
        if args.lockstep:
            out = asyncio.run(fly_lockstep(nav, task, args.connect, mqtt=args.mqtt,
                                           vehicle=args.vehicle,
                                           connect_timeout_s=args.connect_timeout))
        else:
            out = asyncio.run(fly(nav, task, args.connect, mqtt=args.mqtt,
                                  vehicle=args.vehicle, speed_factor=args.speed_factor,
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
    return 0 if out["result"] == ClientResult.SUCCESS else 1

