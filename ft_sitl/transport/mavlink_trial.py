"""One trial flown over MAVLink: the vehicle served here, the navigator in another process.

``run_trial_wire(spec, ...)`` builds the same vehicle, scenario and collision guard as the
in-process :func:`~ft_sitl.missions.trial.run_trial`, serves it with the MAVLink
:class:`~ft_sitl.mavlink.server.SitlServer` on its own instance ports (paced at a speed
factor against the wall clock), optionally publishes it on the MQTT bus, and starts the
navigator as a separate process:

* a registered navigator: ``python -m ft_sitl navigate --algorithm NAME ...`` (MAVSDK
  client, :mod:`ft_sitl.wire.navigate`);
* a user command (the ``command`` pseudo-navigator): any program, started with the
  connection URL, MQTT URL, goal and limits in ``FT_SITL_*`` environment variables
  (docs/wire.md) and ``{connect}``-style placeholders in its arguments.

The protocol is the in-process one's code (:class:`~ft_sitl.missions.protocol.TrialReferee`:
the approach and navigation judges, the metrics, the row), run after every 4 ms of simulated
time. Approach: the navigator process arms, takes off and holds the start itself; navigation
starts when the vehicle is stable at the start, as in-process. A navigator process that exits with
an error fails the trial as ``navigator_error`` (its stderr's last line in the detail); one
that hangs runs into the protocol's timeout; one that never arms fails after
``arm_timeout_s`` of wall time.
"""

from __future__ import annotations

import asyncio
import json
import shlex
import sys
import time
from pathlib import Path

from ft_sitl.autopilot.commander import FENCE_ARM_DENIAL
from ft_sitl.bus.broker import EmbeddedBroker
from ft_sitl.bus.codec import EventType
from ft_sitl.bus.publisher import BusPublisher
from ft_sitl.mavlink.autopilots import DEFAULT_AUTOPILOT
from ft_sitl.missions.campaign_file import COMMAND
from ft_sitl.missions.plan import TrialPlan
from ft_sitl.missions.protocol import (
    APPROACH_TIMEOUT_S,
    Phase,
    TrialFailure,
    TrialOutcome,
    TrialReferee,
    arming_failure,
)
from ft_sitl.missions.results import Outcome
from ft_sitl.missions.spec import TrialSpec
from ft_sitl.navigation.base import Task
from ft_sitl.scenarios.camera import camera_config
from ft_sitl.transport.sitl_bus import SitlBus
from ft_sitl.transport.wire_trial import WireTrial, client_result
from ft_sitl.wire.navigate import ClientResult, task_env

ARM_TIMEOUT_S = 90.0


_BROKER = None  # this process's embedded broker, started on first use


def fly_over_mavlink(spec: TrialSpec, speed_factor: float, mqtt: str | None, *,
                     autopilot: str = DEFAULT_AUTOPILOT) -> dict:
    """One campaign trial over MAVLink, on the bus ``mqtt`` (None: this process's embedded
    broker), served by ``autopilot``'s face: its row."""
    return run_trial_wire(spec, speed_factor=speed_factor, autopilot=autopilot,
                          **worker_bus(mqtt)).row


def worker_bus(mqtt: str | None) -> dict:
    """``run_trial_wire`` keyword arguments for the bus: the given broker, or an embedded
    one started once per process."""
    global _BROKER
    if mqtt is None:

        if _BROKER is None or not _BROKER.running:
            _BROKER = EmbeddedBroker().start()
        mqtt = _BROKER.url
    return {"mqtt": mqtt, "bus_factory": make_bus_factory(mqtt)}


def make_bus_factory(url: str):
    """A factory of the SITL-side bus for one trial's vehicle (its topics named after the
    trial id); the depth camera is the plan's (the benchmark camera for a command), its
    noise drawn from the plan's camera stream for the wire."""

    def factory(server, fleet, plan: TrialPlan, vehicle, camera: bool = True):
        """(``camera`` False: no depth frames, as in lockstep, where they travel in the
        ticks)"""
        cam = plan.frame_camera
        if cam is None:
            cam = camera_config("benchmark", None, None, None)
        bus = SitlBus(lambda on_config: BusPublisher(url, vehicle, on_config=on_config),
                      fleet, 0, scenario=plan.scenario, camera=cam if camera else None,
                      rng=plan.wire_streams.rng("camera"))
        bus.pub.wait_connected(10.0)
        return bus

    return factory


def navigator_argv(plan: TrialPlan, task: Task, connect: str, mqtt: str | None,
                   vehicle: str, speed_factor: float) -> tuple[list[str], dict]:
    """The navigator process's command line and extra environment."""
    spec = plan.spec
    env = task_env(task, connect, mqtt, vehicle)
    env["FT_SITL_SPEED_FACTOR"] = f"{speed_factor:g}"
    if spec.algorithm == COMMAND:
        argv = spec.algorithm_params.get("argv")
        if isinstance(argv, str):
            argv = shlex.split(argv)
        if not (isinstance(argv, list) and argv and all(isinstance(a, str) for a in argv)):
            raise ValueError("command navigator: params.argv must be a command line")
        subst = {"connect": connect, "mqtt": mqtt or "", "vehicle": vehicle,
                 "goal_ned": env["FT_SITL_GOAL_NED"], "start_ned": env["FT_SITL_START_NED"],
                 "max_speed": env["FT_SITL_MAX_SPEED"], "timeout": env["FT_SITL_TIMEOUT_S"]}
        try:
            argv = [a.format(**subst) for a in argv]
        except (KeyError, IndexError, ValueError) as exc:
            raise ValueError(f"command navigator: bad placeholder in argv ({exc}); known: "
                             f"{', '.join('{' + k + '}' for k in subst)}") from None
        return argv, env
    argv = [sys.executable, "-m", "ft_sitl", "navigate", "--algorithm", spec.algorithm,
            "--connect", connect, "--vehicle", vehicle, "--task-json", env["FT_SITL_TASK"],
            "--speed-factor", f"{speed_factor:g}", "--quiet", "--json"]
    for k, v in sorted(plan.navigator_params.items()):
        argv += ["--param", f"{k}={json.dumps(v)}"]
    if mqtt:
        argv += ["--mqtt", mqtt]
    return argv, env


def run_trial_wire(spec: TrialSpec, *, speed_factor: float = 2.0, mqtt: str | None = None,
                   record: bool = False, instance: int | None = None,
                   arm_timeout_s: float = ARM_TIMEOUT_S, log_dir: Path | None = None,
                   bus_factory=None, autopilot: str = DEFAULT_AUTOPILOT,
                   pace_span_s: float | None = None) -> TrialOutcome:
    """Fly one trial with the navigator in another process (module docstring), served by
    ``autopilot``'s face (:mod:`~ft_sitl.transport.faces`; over the ArduCopter face the
    client flies GUIDED and asks for its telemetry's rates itself); with ``pace_span_s``,
    client-paced: the simulated clock never runs more than that past
    the navigator's last message (a starved navigator sees a slower world), the speed
    factor its ceiling (docs/mavlink.md, Pacing)."""
    trial = WireTrial(spec, record=record, instance=instance, log_dir=log_dir,
                      autopilot=autopilot)
    plan, fleet, ref = trial.plan, trial.fleet, trial.ref
    client: dict = {}
    try:
        server, connect = trial.serve(lockstep=False, speed_factor=speed_factor,
                                      pace_span_s=pace_span_s)
        bus = bus_factory(server, fleet, plan, trial.vehicle) if bus_factory else None
        if bus is not None:
            ref.on_start = lambda: bus.event(EventType.TRIAL_START, trial=spec.trial_id)
        try:
            argv, env = navigator_argv(plan, plan.task(wire=True), connect, mqtt,
                                       trial.vehicle, speed_factor)
        except ValueError as exc:
            raise TrialFailure(Outcome.NAVIGATOR_ERROR, str(exc)) from None
        proc = trial.start(argv, env)
        asyncio.run(_serve(server, fleet, ref, proc, spec, speed_factor, arm_timeout_s,
                           bus, trial.out_path))
        client = trial.client_summary()
        if ref.outcome == Outcome.NAVIGATOR_ERROR and not ref.detail:
            ref.detail = trial.client_failed()
    except TrialFailure as f:
        ref.end(f.reason, f.detail)
    finally:
        trial.close()
    # setpoints the client sent (unknown when the judge ended it first)
    ref.metrics.planner_calls = int(client["steps"]) if "steps" in client else -1
    row = ref.finish(replans=-1, wall0=trial.wall0)
    return TrialOutcome(row, ref.trajectory(), plan.scenario)


async def _serve(server, fleet, ref: TrialReferee, proc, spec, speed_factor: float,
                 arm_timeout_s: float, bus, out_path: Path) -> None:
    await server.start()
    wall0 = time.monotonic()
    # the whole trial's wall-clock ceiling: approach + timeout at the speed factor, x3
    wall_limit = arm_timeout_s + 3.0 * (APPROACH_TIMEOUT_S + spec.limits.timeout_s
                                         + spec.limits.hold_s) / speed_factor

    def after_chunk():
        if bus is not None:
            bus.service()
        if ref.after_step():
            server.stop()

    server.on_chunk = after_chunk
    runner = asyncio.create_task(server.run())
    try:
        while not runner.done():
            await asyncio.sleep(0.05)
            if ref.outcome is not None:
                continue
            code = proc.poll()
            cmd = fleet.commanders[0]
            if ref.phase is Phase.APPROACH and not cmd.armed and any(
                    t == FENCE_ARM_DENIAL for _, t in cmd.statustexts):
                # the fence refused the client's arming (protocol 8 on): as in-process
                f = arming_failure(cmd)
                ref.end(f.reason, f.detail)
                server.stop()
            elif code is not None and code != 0 and ref.outcome is None:
                # ft-sitl navigate exits 1 when it gives up (or times out by its own
                # clock): the protocol's "no plan" timeout; anything else is an error
                res = client_result(out_path) if code == 1 else {}
                if res.get("result") in (ClientResult.GAVE_UP, ClientResult.TIMEOUT):
                    ref.end(Outcome.TIMEOUT, f"navigator gave up: {res.get('detail', '')}")
                else:
                    ref.end(Outcome.NAVIGATOR_ERROR)
                server.stop()
            elif ref.phase is Phase.APPROACH and not fleet.commanders[0].armed and \
                    time.monotonic() - wall0 > arm_timeout_s:
                ref.end(Outcome.NAVIGATOR_ERROR, f"the vehicle was not armed within "
                                                 f"{arm_timeout_s:g} s")
                server.stop()
            elif time.monotonic() - wall0 > wall_limit:
                ref.end(Outcome.TIMEOUT, f"wall-clock limit {wall_limit:.0f} s reached "
                                         "(the simulator could not keep its speed factor)")
                server.stop()
        await runner
    finally:
        server.close()
        if bus is not None:
            bus.event(EventType.TRIAL_END, trial=spec.trial_id,
                      outcome=ref.outcome.value if ref.outcome is not None else "?")
            bus.close()

