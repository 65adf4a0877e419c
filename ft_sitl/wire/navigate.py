"""``ft-sitl navigate``: a registered navigator flying a vehicle as a MAVSDK client.

The navigator runs in its own process and talks to the flight controller only through
MAVLink (MAVSDK 4.x): on an ArduPilot vehicle (the ArduCopter face) it first asks for the
telemetry it needs (:data:`ARDUPILOT_RATES_HZ`: ArduPilot streams nothing but HEARTBEAT
until a client asks), then it waits until the vehicle is armable, arms and takes off (MAVSDK
Action) to the start altitude, flies to the start in offboard position mode and holds it
until stable (within 0.3 m, slower than 0.3 m/s for 1 s: the protocol's criterion), then
calls the navigator at its rate and streams every setpoint with MAVSDK Offboard
(position + velocity + acceleration + yaw in local NED, NaN where the navigator leaves an
axis to the next control level; on ArduPilot MAVSDK's take-off and offboard are GUIDED).

State and time. With an MQTT bus (``--mqtt``), observations come from the vehicle's bus
telemetry (world ENU, simulated time stamps) and depth frames from its depth topic (the
navigator's camera is requested through the config topic). Without a bus, observations come
from MAVSDK telemetry and time is wall time x ``speed_factor`` (a navigator that needs
depth frames then cannot run and says so).

The client ends when the goal sphere has been held for the hold time (exit 0), when the
navigation timeout passes (exit 1), when the navigator gives up (exit 1) or fails (exit 3);
in a campaign the judge ends it earlier.
"""

from __future__ import annotations

import asyncio
import json
import logging
import math
import signal
import sys
import time
from enum import StrEnum

import numpy as np

from ft_sitl import frames
from ft_sitl.autopilot.setpoints import Setpoint
from ft_sitl.bus.client import BusClient
from ft_sitl.navigation.base import (
    STABLE_FOR_S,
    STABLE_POS_M,
    STABLE_SPEED_M_S,
    GiveUp,
    Observation,
    Task,
    TaskError,
)
from ft_sitl.physics.quaternion import qto_euler
from ft_sitl.wire.convert import ned_to_world, send, to_offboard
from ft_sitl.wire.tick_observation import tick_observation

log = logging.getLogger("ft_sitl.navigate")



class ClientResult(StrEnum):
    """How ``ft-sitl navigate`` ended (the ``result`` of its JSON summary line)."""

    SUCCESS = "success"
    COLLISION = "collision"
    GAVE_UP = "gave_up"
    TIMEOUT = "timeout"


def task_env(task: Task, connect: str, mqtt: str | None, vehicle: str) -> dict:
    """The environment a navigator process is started with (docs/wire.md): the whole task
    as ``FT_SITL_TASK`` (``Task.to_dict`` as JSON) and its main fields one by one, in
    world ENU and in the flight controller's local NED frame."""
    origin = np.asarray(task.origin, dtype=float)
    env = {
        "FT_SITL_CONNECT": connect, "FT_SITL_VEHICLE": vehicle,
        "FT_SITL_TASK": json.dumps(task.to_dict(), sort_keys=True),
        "FT_SITL_GOAL_ENU": ",".join(f"{x:.3f}" for x in task.goal),
        "FT_SITL_START_ENU": ",".join(f"{x:.3f}" for x in task.start),
        "FT_SITL_ORIGIN_ENU": ",".join(f"{x:.3f}" for x in origin),
        "FT_SITL_GOAL_NED": ",".join(f"{x:.3f}" for x in frames.enu_to_ned(
            np.asarray(task.goal, dtype=float) - origin)),
        "FT_SITL_START_NED": ",".join(f"{x:.3f}" for x in frames.enu_to_ned(
            np.asarray(task.start, dtype=float) - origin)),
        "FT_SITL_START_YAW_DEG": f"{math.degrees(frames.yaw_enu_to_ned(task.start_yaw)):.2f}",
        "FT_SITL_MAX_SPEED": f"{task.limits.max_speed_m_s:g}",
        "FT_SITL_TIMEOUT_S": f"{task.limits.timeout_s:g}",
    }
    if mqtt:
        env["FT_SITL_MQTT"] = mqtt
    return env


def task_from_json(text: str) -> Task:
    """The Task of a JSON document (``--task-json``, ``FT_SITL_TASK``); TaskError naming
    what is wrong."""
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as exc:
        raise TaskError(f"task: not JSON ({exc})") from None
    return Task.from_dict(doc)


#: the telemetry the client asks an ArduPilot vehicle for before it waits for the health,
#: as a MAVSDK user on ArduPilot does (MAVSDK telemetry's ``set_rate_<name>``, Hz): the
#: health (SYS_STATUS, whose pre-arm bit is MAVSDK's armable flag) and home, the position,
#: velocity and attitude the client reads (without a bus: ``_mavsdk_state`` raises the
#: position and attitude to 50 Hz). The PX4 face streams these unasked (PX4's onboard
#: link rates), so nothing is asked of it.
ARDUPILOT_RATES_HZ = {"health": 2.0, "home": 1.0, "gps_info": 2.0, "battery": 1.0,
                      "in_air": 5.0, "position": 10.0, "velocity_ned": 10.0,
                      "position_velocity_ned": 30.0, "attitude_euler": 30.0,
                      "attitude_quaternion": 30.0}


async def ask_ardupilot_rates(drone) -> bool:
    """On an ArduPilot vehicle, ask for :data:`ARDUPILOT_RATES_HZ` (a refused request is
    logged and skipped: a rate request is a wish); whether the vehicle is one."""
    # MAVSDK: loaded only by the navigator client that flies over it
    from mavsdk.asyncio import Autopilot
    from mavsdk.asyncio.plugins.telemetry import TelemetryAsync

    if await drone.autopilot_type() != Autopilot.ARDUPILOT:
        return False
    tel = TelemetryAsync(drone)
    for name, hz in ARDUPILOT_RATES_HZ.items():
        try:
            await getattr(tel, f"set_rate_{name}")(hz)
        except Exception as exc:  # noqa: BLE001 - a rate request is a wish
            log.debug("rate request %s refused: %s", name, exc)
    return True


class NavigateError(RuntimeError):
    """The client could not fly (no vehicle, refused arming, ...); the message says why."""


MAVSDK_MISSING = ("the MAVSDK client needs the Python package 'mavsdk' ({why}); it is a "
                  "dependency of ft-sitl: install it with `pip install 'mavsdk>=4.1'`, or "
                  "reinstall ft-sitl (`bash scripts/setup.sh`, `pip install -e .`)")


def require_mavsdk() -> None:
    """MAVSDK can be imported; else NavigateError saying what to install. Called before
    anything starts, so a broken install is one clear line rather than a traceback (or a
    failed trial) later."""
    try:
        import mavsdk  # noqa: F401  (only checked here; loaded where the client flies)
    except ImportError as exc:
        raise NavigateError(MAVSDK_MISSING.format(why=exc)) from None


class _State:
    """The latest vehicle state, from MAVSDK telemetry or the bus."""

    def __init__(self):
        self.position = None  # world ENU
        self.velocity = None
        self.q = np.array([1.0, 0.0, 0.0, 0.0])  # ENU/FLU
        self.rates = np.zeros(3)
        self.sim_time = None  # from the bus
        self.depth = None
        self.depth_new = False
        self.updated = asyncio.Event()

    @property
    def yaw(self) -> float:
        return float(qto_euler(self.q)[2])


async def _mavsdk_state(drone, state: _State, origin) -> None:
    # MAVSDK: loaded only by the navigator client that flies over it
    from mavsdk.asyncio.plugins.telemetry import TelemetryAsync

    tel = TelemetryAsync(drone)
    for setter in (tel.set_rate_position_velocity_ned, tel.set_rate_attitude_quaternion):
        try:
            await setter(50.0)
        except Exception as exc:  # noqa: BLE001 - a rate request is a wish
            log.debug("rate request refused: %s", exc)

    async def pv():
        async for m in tel.subscribe_position_velocity_ned():
            state.position = ned_to_world([m.position.north_m, m.position.east_m,
                                           m.position.down_m], origin)
            state.velocity = frames.ned_to_enu(np.array([m.velocity.north_m_s,
                                                         m.velocity.east_m_s,
                                                         m.velocity.down_m_s]))
            state.updated.set()

    async def att():
        async for q in tel.subscribe_attitude_quaternion():
            state.q = frames.q_ned_frd_to_enu_flu(np.array([q.w, q.x, q.y, q.z]))

    async def rates():
        async for w in tel.subscribe_attitude_angular_velocity_body():
            state.rates = frames.frd_to_flu(np.array([w.roll_rad_s, w.pitch_rad_s,
                                                      w.yaw_rad_s]))

    await asyncio.gather(pv(), att(), rates())


async def _bus_state(url: str, vehicle: str, state: _State, camera) -> None:
    """Follow the vehicle's bus telemetry (and depth frames when the navigator has a
    camera); reconnect if the broker goes away."""
    # the MQTT client: loaded only when the bus is used
    import aiomqtt

    kinds = ("telemetry", "depth") if camera is not None else ("telemetry",)
    while True:
        try:
            async with BusClient(url, vehicle, kinds=kinds, queue_size=4096) as bus:
                # the request is lost if the simulator is not subscribed yet (it may start
                # after us): repeat it until what we asked for arrives
                async def request():
                    while not (state.sim_time is not None
                               and (camera is None or state.depth is not None)):
                        await bus.request_config(telemetry_rate_hz=100.0,
                                                 depth=camera is not None)
                        await asyncio.sleep(1.0)

                asker = asyncio.create_task(request())
                async for msg in bus:
                    if msg.kind == "telemetry":
                        tm = msg.data
                        state.position = np.array(tm.p_world_m, dtype=float)
                        state.velocity = np.array(tm.v_world_m_s, dtype=float)
                        state.q = np.array(tm.q_world_body, dtype=float)
                        state.rates = np.array(tm.w_body_rad_s, dtype=float)
                        state.sim_time = tm.time_usec * 1e-6
                        state.updated.set()
                    elif msg.kind == "depth":
                        state.depth = msg.data.to_depth_frame()
                        state.depth_new = True
        except aiomqtt.MqttError as exc:
            asker = locals().get("asker")
            if asker is not None:
                asker.cancel()
            log.warning("bus connection lost (%s); reconnecting", exc)
            await asyncio.sleep(0.5)


async def fly(nav, task: Task, connect: str, *, mqtt: str | None = None,
              vehicle: str = "0", speed_factor: float = 1.0,
              connect_timeout_s: float = 60.0, progress=None,
              real_latency: bool = True) -> dict:
    """Fly ``nav`` through MAVSDK; returns a summary dict (``result``: success, timeout,
    gave_up, collision; ``detail``). ``real_latency``: switch the navigator's modelled
    planning latency off (a plan acts when it reaches the flight controller)."""
    require_mavsdk()
    # MAVSDK: loaded only by the navigator client that flies over it
    from mavsdk import ComponentType
    from mavsdk.asyncio import Configuration, Mavsdk
    from mavsdk.asyncio.plugins.action import ActionAsync
    from mavsdk.asyncio.plugins.offboard import OffboardAsync
    from mavsdk.asyncio.plugins.telemetry import TelemetryAsync
    from mavsdk.plugins.offboard import PositionNedYaw

    camera = getattr(nav, "camera", None)
    if camera is not None and not mqtt:
        raise NavigateError(f"navigator {nav.name!r} needs depth frames: give --mqtt URL "
                            "(the simulator's bus)")
    m = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
    tasks = []
    try:
        await m.add_any_connection(connect)
        drone = await m.first_autopilot(timeout_s=connect_timeout_s)
        if drone is None:
            raise NavigateError(f"no autopilot at {connect} within {connect_timeout_s:g} s")
        await ask_ardupilot_rates(drone)
        state = _State()
        origin = np.array(task.origin, dtype=float)
        if mqtt:
            tasks.append(asyncio.create_task(_bus_state(mqtt, vehicle, state, camera)))
        else:
            tasks.append(asyncio.create_task(_mavsdk_state(drone, state, origin)))
        action, off, tel = ActionAsync(drone), OffboardAsync(drone), TelemetryAsync(drone)

        async def first(gen, pred, what, timeout):
            async def scan():
                async for v in gen:
                    if pred(v):
                        return v
            try:
                return await asyncio.wait_for(scan(), timeout)
            except TimeoutError:
                raise NavigateError(f"timed out waiting for {what}") from None

        await first(tel.subscribe_health(), lambda h: h.is_armable, "the vehicle to be armable",
                    connect_timeout_s)
        wall_limit = 60.0 / speed_factor + 30.0
        start = np.array(task.start, dtype=float)
        start_ned = frames.enu_to_ned(start - origin)
        yaw_ned_deg = math.degrees(frames.wrap_pi(frames.yaw_enu_to_ned(task.start_yaw)))
        await action.set_takeoff_altitude(float(start[2] - origin[2]))
        if task.observe_approach:
            _reset(nav, task, real_latency)
        await action.arm()
        observer = None
        if task.observe_approach:
            observer = asyncio.create_task(_observe(nav, state, speed_factor,
                                                    task.map_fusion_hz))
            tasks.append(observer)
        await action.takeoff()
        await first(tel.subscribe_position_velocity_ned(),
                    lambda p: abs(-p.position.down_m - (start[2] - origin[2])) < STABLE_POS_M,
                    "the take-off altitude", wall_limit)
        target = PositionNedYaw(*[float(x) for x in start_ned], yaw_ned_deg)
        await off.set_position_ned(target)
        await off.start()
        while state.position is None:
            await asyncio.wait_for(state.updated.wait(), wall_limit)
            state.updated.clear()
        stable_since = None
        t_wall0 = time.monotonic()
        while True:  # hold the start until stable (the protocol's criterion)
            await off.set_position_ned(target)
            now = _now(state, t_wall0, speed_factor)
            ok = (np.linalg.norm(state.position - start) < STABLE_POS_M
                  and np.linalg.norm(state.velocity) < STABLE_SPEED_M_S)
            if ok and stable_since is None:
                stable_since = now
            elif not ok:
                stable_since = None
            if stable_since is not None and now - stable_since >= STABLE_FOR_S:
                break
            if time.monotonic() - t_wall0 > wall_limit:
                raise NavigateError("could not hold the start (30 s simulated)")
            await asyncio.sleep(0.02 / speed_factor)
        crash: list[str] = []

        async def watch_texts():  # the simulator announces a crash as a STATUSTEXT
            async for st in tel.subscribe_status_text():
                if st.text.startswith("Collision"):
                    crash.append(st.text)
                    state.updated.set()

        tasks.append(asyncio.create_task(watch_texts()))
        if observer is not None:
            observer.cancel()  # navigation starts: steps take the frames from here on
        return await _navigate(nav, task, off, state, t_wall0, speed_factor, progress, crash,
                               real_latency)
    finally:
        for t in tasks:
            t.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)
        m.destroy()


def _now(state: _State, t_wall0: float, speed_factor: float) -> float:
    """Simulated seconds: the bus's stamp, or wall time x the speed factor."""
    if state.sim_time is not None:
        return state.sim_time
    return (time.monotonic() - t_wall0) * speed_factor


def _reset(nav, task: Task, real_latency: bool) -> None:
    """The navigator's reset with the trial's task."""
    if real_latency and hasattr(nav, "latency"):
        # over the wire the latency is real (compute, transport, the flight controller's
        # input): the modelled one would count it twice
        nav.latency = 0.0
        if hasattr(nav, "measured_latency"):
            nav.measured_latency = False
    nav.reset(task)


class _MapTimer:
    """When the navigator's map takes the latest depth frame: every ``1 / hz`` s of its
    clock (protocol 6 on), or whenever one arrives (``hz`` None)."""

    def __init__(self, hz: float | None) -> None:
        self.period = 1.0 / hz if hz else 0.0
        self.next = 0.0

    def fires(self, t: float) -> bool:
        if not self.period:
            return True
        if t + 1e-9 < self.next:
            return False
        self.next += self.period * (1 + int((t - self.next) // self.period))
        return True


async def _observe(nav, state: _State, speed_factor: float,
                   fusion_hz: float | None = None) -> None:
    """Before navigation (protocol 3 on): the depth frames go to the navigator's
    ``observe`` (every one, or the latest at each tick of its map's timer), its clock
    counting from arming."""
    t_wall0 = time.monotonic()
    t0 = state.sim_time
    timer = _MapTimer(fusion_hz)
    while True:
        await asyncio.sleep(0.005)
        if state.position is None:
            continue
        if t0 is None:
            t0 = state.sim_time
        now = _now(state, t_wall0, speed_factor)
        if not timer.fires(now - (t0 if t0 is not None else 0.0)) or not state.depth_new:
            continue
        depth, state.depth_new = state.depth, False
        obs = Observation(time_s=now - (t0 if t0 is not None else 0.0),
                          position=state.position.copy(), velocity=state.velocity.copy(),
                          yaw=state.yaw, attitude=state.q.copy(),
                          angular_velocity=state.rates.copy(), depth=depth)
        await asyncio.get_running_loop().run_in_executor(None, nav.observe, obs)


async def _navigate(nav, task: Task, off, state: _State, t_wall0: float,
                    speed_factor: float, progress, crash: list,
                    real_latency: bool = True) -> dict:

    if not task.observe_approach:
        _reset(nav, task, real_latency)
    t0 = _now(state, t_wall0, speed_factor)
    period = 1.0 / float(nav.rate_hz)
    next_step = 0.0
    goal = np.array(task.goal, dtype=float)
    entered = None
    steps = 0
    timer = _MapTimer(task.map_fusion_hz)
    while True:
        await state.updated.wait()
        state.updated.clear()
        if crash:
            return {"result": ClientResult.COLLISION.value, "detail": crash[0], "steps": steps}
        t = _now(state, t_wall0, speed_factor) - t0
        if t + 1e-9 < next_step:
            continue
        # a slow navigator skips steps instead of falling behind the vehicle
        next_step = max(next_step + period, t - period / 2.0 + period)
        depth = None
        if timer.fires(t) and state.depth_new:
            depth, state.depth_new = state.depth, False
        obs = Observation(time_s=t, position=state.position.copy(),
                          velocity=state.velocity.copy(), yaw=state.yaw,
                          attitude=state.q.copy(), angular_velocity=state.rates.copy(),
                          depth=depth)
        try:
            # in a worker thread: the event loop keeps reading MAVLink and the bus while
            # the navigator computes (a long replan must not overflow the bus queue)
            sp = await asyncio.get_running_loop().run_in_executor(None, nav.step, obs)
        except GiveUp as exc:
            return {"result": ClientResult.GAVE_UP.value, "detail": str(exc), "steps": steps}
        if not isinstance(sp, Setpoint):
            raise NavigateError(f"navigator returned {type(sp).__name__}, not a Setpoint")
        await send(off, to_offboard(sp, task.origin))
        steps += 1
        if progress is not None:
            progress(t, obs)
        dist = float(np.linalg.norm(state.position - goal))
        if dist <= task.limits.goal_radius_m:
            entered = t if entered is None else entered
            if t - entered >= task.limits.hold_s:
                return {"result": ClientResult.SUCCESS.value,
                        "detail": f"goal held at t = {t:.1f} s", "steps": steps}
        else:
            entered = None
        if entered is None and t >= task.limits.timeout_s:
            return {"result": ClientResult.TIMEOUT.value,
                    "detail": f"{dist:.1f} m from the goal after {task.limits.timeout_s:g} s",
                    "steps": steps}


#: wall seconds between a lockstep client's "ready" messages until the first tick comes
READY_REPEAT_S = 0.5


async def fly_lockstep(nav, task: Task, connect: str, *, mqtt: str, vehicle: str = "0",
                       connect_timeout_s: float = 60.0) -> dict:
    """Answer a lockstep trial's ticks (:mod:`ft_sitl.transport.lockstep`) with ``nav``
    until the simulator ends the trial (SIGTERM: the summary line is printed then, with
    the steps and the navigator's replans) or the navigator gives up (``gave_up``).

    The simulator flies the approach; the navigator is reset with ``task`` first (its
    modelled latency stays: in lockstep the wire adds none). Each tick's observation comes
    on the bus, bit for bit; an ``observe`` tick goes to ``nav.observe``, a ``step`` tick
    to ``nav.step``, whose setpoint goes out with MAVSDK Offboard (the first: setpoint,
    offboard mode, setpoint). Then the tick is acknowledged on the same MAVLink connection
    with a TIMESYNC: ``tc1`` the tick's simulated time in ns, ``ts1`` its number (0: ready).
    """
    require_mavsdk()
    # MAVSDK and the MQTT client: loaded only by the navigator client that flies over them
    from mavsdk import ComponentType
    from mavsdk.asyncio import Configuration, Mavsdk
    from mavsdk.asyncio.plugins.mavlink_direct import MavlinkDirectAsync
    from mavsdk.asyncio.plugins.offboard import OffboardAsync
    from mavsdk.plugins.mavlink_direct import MavlinkMessage

    nav.reset(task)
    state = {"steps": 0}

    def summary(result: str, detail: str) -> dict:
        replans = getattr(nav, "replans", -1)
        return {"result": result, "detail": detail, "steps": state["steps"],
                "replans": replans if isinstance(replans, int) else -1}

    def stopped(signum, frame):  # the simulator ended the trial: say what was done
        sys.stdout.write(json.dumps(summary("stopped", "the simulator ended the trial"))
                         + "\n")
        sys.stdout.flush()
        raise SystemExit(0)

    signal.signal(signal.SIGTERM, stopped)
    m = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
    try:
        await m.add_any_connection(connect)
        drone = await m.first_autopilot(timeout_s=connect_timeout_s)
        if drone is None:
            raise NavigateError(f"no autopilot at {connect} within {connect_timeout_s:g} s")
        off, direct = OffboardAsync(drone), MavlinkDirectAsync(drone)

        async def ack(time_usec: int, seq: int) -> None:
            fields = {"tc1": max(1, int(time_usec) * 1000), "ts1": int(seq),
                      "target_system": 1, "target_component": 1}
            await direct.send_message(MavlinkMessage("TIMESYNC", 0, 0, 1, 1,
                                                     json.dumps(fields)))

        offboard = False
        last = 0
        async with BusClient(mqtt, vehicle, kinds=("tick",), queue_size=4096) as bus:
            async def ready():
                while last == 0:
                    await ack(0, 0)
                    await asyncio.sleep(READY_REPEAT_S)

            asker = asyncio.create_task(ready())
            try:
                async for msg in bus:
                    tick = msg.data
                    if tick.seq <= last:
                        continue  # a repeated delivery (QoS 1)
                    if tick.seq != last + 1:
                        raise NavigateError(f"lockstep: tick {last + 1} was lost (got "
                                            f"{tick.seq})")
                    last = tick.seq
                    obs = tick_observation(tick)
                    try:
                        if tick.phase == "observe":
                            nav.observe(obs)
                        else:
                            sp = nav.step(obs)
                    except GiveUp as exc:
                        return summary(ClientResult.GAVE_UP.value, str(exc))
                    if tick.phase == "step":
                        if not isinstance(sp, Setpoint):
                            raise NavigateError(f"navigator returned {type(sp).__name__}, "
                                                "not a Setpoint")
                        cmd = to_offboard(sp, task.origin)
                        await send(off, cmd)
                        if not offboard:  # PX4: a setpoint first, then the mode
                            await off.start()
                            await send(off, cmd)
                            offboard = True
                        state["steps"] += 1
                    await ack(tick.time_usec, tick.seq)
            finally:
                asker.cancel()
        raise NavigateError("the bus closed")
    finally:
        m.destroy()
