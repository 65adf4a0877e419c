"""One trial flown over MAVLink in lockstep: the in-process driver, its navigator in another
process.

``run_trial_lockstep(spec, ...)`` flies the trial with the in-process protocol driver
(:func:`ft_sitl.missions.trial.fly`: the same approach, the same physics steps, the same
judge calls, the same camera frames from the same noise stream) and answers the driver's
navigator calls through :class:`LockstepPilot`, from ``ft-sitl navigate --lockstep`` in
another process:

1. the vehicle is served on MAVLink (by the PX4 face, or with ``autopilot="ardupilot"``
   the ArduCopter face: :mod:`ft_sitl.transport.faces`; its links read only while the
   clock stands) and on the bus; the client connects with MAVSDK, subscribes to the bus's
   ``tick`` topic and says it is ready with a TIMESYNC;
2. wherever the in-process driver would call ``observe`` (a camera frame during the
   approach) or ``step`` (a navigation tick), the simulator publishes the observation,
   bit for bit, as a tick (:mod:`ft_sitl.bus.tick`) and holds its clock;
3. the client calls its navigator, sends a step's setpoint with MAVSDK Offboard (the first
   one: setpoint, offboard mode, setpoint, as the in-process driver does; on ArduPilot
   MAVSDK's offboard mode is GUIDED), then
   acknowledges the tick on the same MAVLink connection: a TIMESYNC whose ``tc1`` is the
   tick's simulated time in nanoseconds (the client's clock is the simulator's) and whose
   ``ts1`` is the tick's number; the flight controller takes the setpoint as it arrives;
4. the clock goes on when the acknowledgement has arrived: behind it on the link, the
   setpoint already has.

Setpoints cross MAVLink as float32 and protocol 10 flies in-process setpoints through the
same conversion (:mod:`ft_sitl.autopilot.wire_setpoint`), so from protocol 10 the row is
the in-process row column for column but the wall times (``wall_time_s``,
``planner_time_s``); docs/wire.md, "Lockstep".
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

from ft_sitl.autopilot.commander import MAIN_OFFBOARD
from ft_sitl.bus.codec import EventType
from ft_sitl.mavlink.outgoing import Outgoing
from ft_sitl.mavlink.server import SitlServer
from ft_sitl.missions.campaign_file import COMMAND
from ft_sitl.missions.protocol import APPROACH_TIMEOUT_S, TrialFailure, TrialOutcome
from ft_sitl.missions.results import Outcome
from ft_sitl.missions.spec import TrialSpec, TrialSpecError
from ft_sitl.missions.trial import fly, replan_count
from ft_sitl.missions.watchdog import WallWatchdog, beat
from ft_sitl.navigation.registry import create
from ft_sitl.transport.faces import DEFAULT_AUTOPILOT
from ft_sitl.transport.sitl_bus import SitlBus
from ft_sitl.transport.wire_trial import WireTrial, client_result, tail
from ft_sitl.wire.navigate import ClientResult, task_env
from ft_sitl.wire.tick_observation import observation_tick

#: wall seconds the client has to connect and say it is ready
READY_TIMEOUT_S = 120.0
#: wall seconds one tick may take the client (its navigator's step included)
TICK_TIMEOUT_S = 300.0
#: wall seconds between the vehicle's heartbeats while the client connects: MAVSDK finds
#: the autopilot by its heartbeat, and the held clock's top-up (once a wall second) made
#: every trial's client wait half a second for it on average (docs/benchmarks.md)
READY_HEARTBEAT_S = 0.05
#: the messages that carry an offboard setpoint
SETPOINT_MESSAGES = frozenset({"SET_POSITION_TARGET_LOCAL_NED", "SET_POSITION_TARGET_GLOBAL_INT",
                               "SET_ATTITUDE_TARGET"})


class LockstepPilot:
    """The driver's navigator calls answered by a client process over the bus and MAVLink
    (module docstring). ``navigator``: an instance of the trial's navigator, made here only
    to read what the driver asks of it (camera, rate, whether it wants the movers' truth);
    it is never stepped."""

    def __init__(self, navigator, server: SitlServer, bus: SitlBus, proc, out_path: Path,
                 err_path: Path):
        self.navigator = navigator
        self.server, self.bus, self.proc = server, bus, proc
        self.out_path, self.err_path = out_path, err_path
        self.seq = 0
        self.acked = -1
        #: setpoint messages received so far
        self.setpoints = 0
        server.on_message = self._on_message

    def _on_message(self, vehicle: int, m) -> None:
        t = m.get_type()
        if t == "TIMESYNC" and m.tc1 != 0:  # a client's clock: its acknowledgement
            self.acked = max(self.acked, int(m.ts1))
        elif t in SETPOINT_MESSAGES:
            self.setpoints += 1

    def wait_ready(self) -> None:
        """Until the client has connected and said so (TIMESYNC, ts1 0), the vehicle's
        heartbeat sent every :data:`READY_HEARTBEAT_S` meanwhile."""
        self._wait(0, READY_TIMEOUT_S, "connect", heartbeat_s=READY_HEARTBEAT_S)

    def _wait(self, seq: int, timeout_s: float, what: str,
              heartbeat_s: float | None = None, setpoints_past: int | None = None) -> None:
        """Until tick ``seq`` is acknowledged (and, with ``setpoints_past``, more than that
        many setpoint messages have arrived)."""
        deadline = time.monotonic() + timeout_s
        beat = 0.0

        def waiting() -> bool:
            return self.acked < seq or (setpoints_past is not None
                                        and self.setpoints <= setpoints_past)

        while waiting():
            if heartbeat_s is not None and time.monotonic() - beat >= heartbeat_s:
                beat = time.monotonic()
                for a in self.server.agents:
                    self.server.send_all(a.i, [Outgoing(a.heartbeat())])
            self.server.pump(0.02 if heartbeat_s is None else min(0.02, heartbeat_s))
            if not waiting():
                break
            code = self.proc.poll()
            if code is not None:
                raise self._client_ended(code)
            if time.monotonic() > deadline:
                raise TrialFailure(Outcome.NAVIGATOR_ERROR, f"the navigator process did not "
                                                            f"{what} within {timeout_s:g} s")

    def _client_ended(self, code: int) -> TrialFailure:
        res = client_result(self.out_path)
        if code == 1 and res.get("result") == ClientResult.GAVE_UP:
            return TrialFailure(Outcome.TIMEOUT, f"navigator gave up: {res.get('detail', '')}")
        return TrialFailure(Outcome.NAVIGATOR_ERROR, tail(self.err_path))

    def _exchange(self, phase: str, obs) -> None:
        self.seq += 1
        # a step is answered by its setpoint and its acknowledgement: in MAVSDK the setpoint
        # (Offboard) and the acknowledgement (MavlinkDirect, straight onto the connection)
        # leave by different paths, whose order MAVSDK does not promise, so the clock
        # waits for both (docs/wire.md, "Lockstep")
        setpoints = self.setpoints if phase == "step" else None
        tick = observation_tick(self.seq, phase, self.server.fleet.time_us, obs)
        deadline = time.monotonic() + 10.0
        while not self.bus.pub.publish_tick(tick):  # the broker is away: wait for it
            if time.monotonic() > deadline:
                raise TrialFailure(Outcome.NAVIGATOR_ERROR, "the bus did not take a tick")
            time.sleep(0.01)
        self._wait(self.seq, TICK_TIMEOUT_S, f"answer tick {self.seq}",
                   setpoints_past=setpoints)

    # -- the driver's calls ------------------------------------------------------------------
    def reset(self, task, m) -> None:
        pass  # the client resets its navigator with the same task before it says ready

    def observe(self, obs, m) -> None:
        self._exchange("observe", obs)

    def tick(self, fleet, obs, m) -> None:
        m.planner_calls += 1
        self._exchange("step", obs)
        if fleet.commanders[0].main_mode != MAIN_OFFBOARD:
            raise TrialFailure(Outcome.NAVIGATOR_ERROR,
                               "the flight controller refused offboard mode")

    def advanced(self, fleet) -> None:
        self.server.service()
        self.bus.service()
        beat()  # the clock went on: the executor counts the wall budget from here


def lockstep_argv(plan, connect: str, mqtt: str, vehicle: str) -> tuple[list[str], dict]:
    """The client's command line and extra environment."""
    task = plan.task(wire=True)
    env = task_env(task, connect, mqtt, vehicle)
    argv = [sys.executable, "-m", "ft_sitl", "navigate", "--algorithm", plan.spec.algorithm,
            "--connect", connect, "--vehicle", vehicle, "--task-json", env["FT_SITL_TASK"],
            "--mqtt", mqtt, "--lockstep", "--quiet", "--json"]
    for k, v in sorted(plan.navigator_params.items()):
        argv += ["--param", f"{k}={json.dumps(v)}"]
    return argv, env


def run_trial_lockstep(spec: TrialSpec, *, mqtt: str, bus_factory, record: bool = False,
                       instance: int | None = None, log_dir: Path | None = None,
                       autopilot: str = DEFAULT_AUTOPILOT) -> TrialOutcome:
    """Fly one trial in lockstep with its navigator in another process (module
    docstring), served by ``autopilot``'s face. ``bus_factory`` makes the simulator's side
    of the bus (its camera is not used: frames travel in the ticks)."""
    if spec.algorithm == COMMAND:
        raise TrialSpecError("a command navigator cannot fly in lockstep (it does not answer "
                             "ticks): fly it free-running")
    trial = WireTrial(spec, record=record, instance=instance, log_dir=log_dir,
                      autopilot=autopilot)
    plan, fleet, ref = trial.plan, trial.fleet, trial.ref
    bus = None
    try:
        nav = create(spec.algorithm, dict(plan.navigator_params))
        server, connect = trial.serve(lockstep=True)
        bus = bus_factory(server, fleet, plan, trial.vehicle, camera=False)
        ref.on_start = lambda: bus.event(EventType.TRIAL_START, trial=spec.trial_id)
        argv, env = lockstep_argv(plan, connect, mqtt, trial.vehicle)
        pilot = LockstepPilot(nav, server, bus, trial.start(argv, env), trial.out_path,
                              trial.err_path)
        server.service()
        pilot.wait_ready()
        # a ceiling against a hang only: the ticks wait as long as the client computes
        budget = READY_TIMEOUT_S + 20.0 * (APPROACH_TIMEOUT_S + spec.limits.timeout_s
                                           + spec.limits.hold_s)
        fly(plan, fleet, ref, pilot, WallWatchdog(time.perf_counter(), budget))
    except TrialFailure as f:
        ref.end(f.reason, f.detail)
    finally:
        trial.stop_client()
        if bus is not None:
            bus.event(EventType.TRIAL_END, trial=spec.trial_id,
                      outcome=ref.outcome.value if ref.outcome is not None else "?")
            bus.close()
        trial.close()
    client = trial.client_summary() if trial.proc is not None else {}
    row = ref.finish(replans=replan_count(client.get("replans", -1)), wall0=trial.wall0)
    return TrialOutcome(row, ref.trajectory(), plan.scenario)
