"""PX4 in the loop: a real PX4 SITL flies our physics in lockstep over its simulator link.

PX4's ``simulator_mavlink`` module (src/modules/simulation/simulator_mavlink/
SimulatorMavlink.cpp) is the other end. What it does, and what this bridge does for it:

- **Connection.** PX4 is the TCP *client*: its startup script (px4-rc.mavlinksim) runs
  ``simulator_mavlink start -c $((4560 + px4_instance))`` and PX4 retries ``connect`` every
  0.5 ms until a simulator listens. The bridge listens on ``host:4560 + instance`` and
  serves one PX4 at a time. On connecting, PX4 sends a HEARTBEAT and a COMMAND_LONG
  (SET_MESSAGE_INTERVAL for HIL_STATE_QUATERNION); both are counted as ``other_messages``.
- **Boot.** PX4's startup script blocks until the first HIL_SENSOR has set its clock
  (``has_initialized``). So on every new connection the bridge resets the vehicle to its
  spawn point and at once starts sending HIL_SENSOR frames (plus HIL_GPS when due, plus
  HIL_STATE_QUATERNION with ``ground_truth``), stepping the physics with the motors off,
  paced to the wall clock (``speed_factor``, 1 if None), until the first
  HIL_ACTUATOR_CONTROLS arrives.
- **Lockstep.** PX4 answers each HIL_SENSOR with one HIL_ACTUATOR_CONTROLS whose flags
  bit 0 (HIL_ACTUATOR_CONTROLS_FLAGS_LOCKSTEP) is set in lockstep builds. From then on a
  frame is: step the physics by one IMU period (1/imu_rate_hz) with the last motor command
  -> send HIL_SENSOR stamped with the simulated time_usec -> wait for the answer -> apply
  it. PX4's clock is the time_usec of HIL_SENSOR, so PX4 (and its ground-station
  timeouts) runs on simulated time, and the physics advances only when PX4 answers.
  ``speed_factor=None`` runs as fast as the two can; a number paces to the wall clock.
  An answer stamped (time_usec) before the frame it would answer is a late duplicate: its
  controls are applied, but it does not release the next frame.
  A PX4 built without lockstep (flag clear) is served free-running at the wall clock with
  its latest controls.
- **Actuators.** ``controls[i]`` is PX4's output i (PWM_MAIN_FUNCi; 101..104 = Motor1..4
  in the none_iris airframe), 0..1 for motors, all zero while disarmed
  (``actuator_controls_from_outputs``). ``mode`` carries MAV_MODE_FLAG_SAFETY_ARMED.
  Outputs are mapped from PX4's motor order to our rotor order by matching positions and
  spin directions (:func:`px4_motor_map`); a layout that does not match none_iris is
  refused when the bridge is built.
- **Sensors.** HIL_SENSOR: accel (m/s^2, specific force, FRD), gyro (rad/s, FRD), mag
  (Gauss, FRD), abs_pressure (hPa), pressure_alt (m), temperature (deg C),
  ``fields_updated`` with PX4's groups (accel 0x7, gyro 0x38, mag 0x1C0, baro
  0x1A00 = abs pressure + pressure alt + temperature, diff pressure 0x400), id 0 (the
  IMU that drives PX4's lockstep). HIL_GPS: lat/lon (1e-7 deg), alt (mm AMSL), eph/epv
  (PX4 reads them as cm), vel/vn/ve/vd (cm/s), cog (cdeg), satellites, fix type. See
  :mod:`ft_sitl.bridge.sensors`.
- **Disconnect.** When PX4 goes away (EOF, reset) or another PX4 connects, the bridge
  drops the old connection, resets the vehicle and boots the new PX4 as above. The
  simulated clock keeps running forward (monotonic time_usec over the bridge's life).
- **Robustness.** Bytes that are not MAVLink, bad checksums and messages PX4 does not send
  are counted (``bad_packets``, ``unexpected_messages``) and logged, never fatal.
- **Collisions.** In a scenario, a collision crashes the vehicle (BridgeVehicle): its
  motors stay off whatever PX4 commands; PX4 sees the fall in its sensors.

``Px4Bridge`` opens no socket when built: :meth:`Px4Bridge.run` (blocking) or
:meth:`Px4Bridge.start` (a background thread) listen and serve until :meth:`Px4Bridge.stop`.
:func:`run_px4_bridge` is the command-line entry point.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import select
import socket
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from pymavlink.dialects.v20 import common as mav

from ft_sitl import G, frames
from ft_sitl.bridge.sensors import MagField, SensorNoise, SensorSuite
from ft_sitl.bridge.vehicle import BridgeVehicle, Crash, spawn_yaw_from_heading
from ft_sitl.physics.catalog import PlatformRegistry
from ft_sitl.physics.layouts import get_layout

log = logging.getLogger(__name__)

PX4_BASE_PORT = 4560  #: PX4 connects to 4560 + instance (px4-rc.mavlinksim)
#: PX4 none_iris (ROMFS/px4fmu_common/init.d-posix/airframes/10016_none_iris): rotor
#: positions CA_ROTORi_PX/PY (m, body FRD) and spin (CA_ROTORi_KM > 0: counter-clockwise)
NONE_IRIS_MOTORS_FRD = ((0.1515, 0.245), (-0.1515, -0.1875), (0.1515, -0.245),
                        (-0.1515, 0.1875))
NONE_IRIS_SPINS = (1, 1, -1, -1)
#: largest azimuth difference (deg) between a none_iris motor and the rotor it maps to
MOTOR_MATCH_TOLERANCE_DEG = 20.0

FIELDS_ACCEL = 0x007
FIELDS_GYRO = 0x038
FIELDS_MAG = 0x1C0
FIELDS_BARO = 0x200 | 0x800 | 0x1000  # abs pressure, pressure alt, temperature
FIELDS_DIFF_PRESSURE = 0x400
LOCKSTEP_FLAG = mav.HIL_ACTUATOR_CONTROLS_FLAGS_LOCKSTEP
ARMED_FLAG = mav.MAV_MODE_FLAG_SAFETY_ARMED
#: our MAVLink identity on the simulator link (PX4 dispatches on the message id only)
BRIDGE_SYSID = 1
BRIDGE_COMPID = mav.MAV_COMP_ID_IMU
#: messages PX4's simulator_mavlink sends besides HIL_ACTUATOR_CONTROLS
PX4_OTHER_MESSAGES = frozenset({"HEARTBEAT", "COMMAND_LONG"})
#: how often (s) a blocked wait looks at stop() and at a new connection
_POLL_S = 0.05
#: pacing never catches up more than this (s) of wall time in a burst
_PACE_SLACK_S = 0.1


class BridgeError(RuntimeError):
    """The bridge cannot serve (port taken, bad configuration); the message says why."""


class MotorMappingError(ValueError):
    """A platform's rotor layout does not match PX4's none_iris motors."""


def px4_motor_map(positions_flu, spins, *, platform_name: str = "platform",
                  layout_name: str = "?",
                  tolerance_deg: float = MOTOR_MATCH_TOLERANCE_DEG) -> tuple[int, ...]:
    """Our rotor index for each PX4 none_iris motor (``u_ours[map[i]] = controls[i]``).

    Each PX4 motor is matched to the rotor of ours whose azimuth (direction from the
    centre, seen from above) is within ``tolerance_deg`` and whose spin direction is the
    same; the matching must be one-to-one. Raises :class:`MotorMappingError` otherwise.
    """
    pos = np.asarray(positions_flu, dtype=float)
    spins = np.asarray(spins, dtype=float).reshape(-1)
    n = len(NONE_IRIS_MOTORS_FRD)
    where = f"{platform_name} (layout {layout_name})"
    if pos.shape != (n, 3) or len(spins) != n:
        raise MotorMappingError(
            f"{where}: {len(pos)} rotors, but PX4's none_iris airframe has {n} motors")
    ours_az = np.degrees(np.arctan2(pos[:, 1], pos[:, 0]))
    mapping: list[int] = []
    for i, ((x_frd, y_frd), spin) in enumerate(zip(NONE_IRIS_MOTORS_FRD, NONE_IRIS_SPINS)):
        az = math.degrees(math.atan2(-y_frd, x_frd))  # FRD -> FLU: y flips
        diff = np.abs((ours_az - az + 180.0) % 360.0 - 180.0)
        j = int(np.argmin(diff))
        if diff[j] > tolerance_deg or spins[j] != spin:
            raise MotorMappingError(
                f"{where}: PX4 none_iris motor {i + 1} (x {x_frd:+.4f} m, y {y_frd:+.4f} m FRD,"
                f" azimuth {az:.1f} deg FLU, {'CCW' if spin > 0 else 'CW'}) has no rotor of ours"
                f" within {tolerance_deg:g} deg with the same spin (nearest: rotor {j + 1} at "
                f"{ours_az[j]:.1f} deg, {'CCW' if spins[j] > 0 else 'CW'}); the PX4 bridge "
                f"flies quad-X layouts only")
        if j in mapping:
            raise MotorMappingError(
                f"{where}: PX4 none_iris motors {mapping.index(j) + 1} and {i + 1} both match"
                f" our rotor {j + 1}; the layout cannot be matched one-to-one")
        mapping.append(j)
    return tuple(mapping)


def hover_output(platform) -> float:
    """The motor output (0..1) at which all rotors together carry the platform's weight:
    rotor speed u * w_max, thrust c_T w^2 per rotor."""

    n = get_layout(platform.layout).n_rotors
    w_hover = math.sqrt(platform.mass_kg * G / (n * platform.thrust_coefficient))
    return w_hover / platform.rotor_speed_max_rad_s


def px4_parameters(platform, motor_map=None) -> dict[str, float]:
    """PX4 parameters that describe our platform to PX4's none_iris airframe.

    - CA_ROTORi_PX / _PY (m, body FRD) and CA_ROTORi_KM (torque / thrust, m; > 0 for a
      counter-clockwise rotor): our rotor geometry and drag-torque ratio for PX4 motor i,
      so PX4's control allocation mixes for the vehicle it actually flies;
    - THR_MDL_FAC = 1: the plant commands the rotor speed u * w_max, so thrust goes with
      u^2 (PX4's model: thrust = f u^2 + (1 - f) u);
    - MPC_THR_HOVER: the normalised thrust at hover, (hover output)^2, clamped to PX4's
      range 0.1..0.8 (the hover thrust estimator refines it in flight).

    Set them with ``param set`` in PX4's shell, or as environment variables
    ``PX4_PARAM_<NAME>=<value>`` when starting PX4 (its rcS applies those).
    """

    layout = get_layout(platform.layout)
    pos = layout.rotor_positions(platform.arm_length_m)
    spins = layout.spins()
    if motor_map is None:
        motor_map = px4_motor_map(pos, spins, platform_name=platform.name,
                                  layout_name=platform.layout)
    out: dict[str, float] = {}
    for i, j in enumerate(motor_map):
        out[f"CA_ROTOR{i}_PX"] = round(float(pos[j, 0]), 4)
        out[f"CA_ROTOR{i}_PY"] = round(float(-pos[j, 1]), 4)  # FLU y (left) -> FRD y (right)
        out[f"CA_ROTOR{i}_KM"] = round(float(spins[j] * platform.torque_thrust_ratio_m), 4)
    out["THR_MDL_FAC"] = 1.0
    out["MPC_THR_HOVER"] = round(min(0.8, max(0.1, hover_output(platform) ** 2)), 3)
    return out


@dataclass
class Px4BridgeStats:
    """Counters of a :class:`Px4Bridge` (a snapshot: ``Px4Bridge.stats``)."""

    connections: int = 0  #: PX4 connections accepted
    connected: bool = False
    lockstep: bool = False  #: the last actuator message had the lockstep flag
    px4_armed: bool = False  #: the last actuator message had MAV_MODE_FLAG_SAFETY_ARMED
    sensor_frames: int = 0  #: HIL_SENSOR sent
    boot_frames: int = 0  #: of which sent before a connection's first actuator message
    gps_frames: int = 0  #: HIL_GPS sent
    ground_truth_frames: int = 0  #: HIL_STATE_QUATERNION sent
    steps: int = 0  #: physics advances of one IMU period
    actuator_messages: int = 0  #: HIL_ACTUATOR_CONTROLS received
    stale_actuator_messages: int = 0  #: of which stamped before the frame they would answer
    other_messages: int = 0  #: HEARTBEAT / COMMAND_LONG (PX4 sends them on connecting)
    unexpected_messages: int = 0  #: valid MAVLink that PX4's simulator link never sends
    bad_packets: int = 0  #: bytes that are not MAVLink, bad checksums
    sim_time_us: int = 0
    achieved_speed_factor: float | None = None  #: sim s / wall s over the current connection
    crash: Crash | None = None


class _Disconnected(Exception):
    pass


class _Replaced(Exception):
    def __init__(self, sock: socket.socket, addr):
        super().__init__(addr)
        self.sock = sock
        self.addr = addr


class _Stopped(Exception):
    pass


class Px4Bridge:
    """Our physics, sensors and scenario as PX4 SITL's simulator (see the module docstring).

    ``platform``: a :class:`~ft_sitl.physics.platform.Platform` whose layout matches PX4's
    none_iris motors (quad-X). ``scenario``: optional world (collisions crash the vehicle;
    the vehicle spawns at its takeoff point). ``instance``: PX4 instance, port 4560 +
    instance. ``speed_factor``: None = as fast as lockstep allows, else simulated seconds
    per wall second. ``imu_rate_hz``: HIL_SENSOR rate = lockstep frame rate (PX4 SITL sets
    IMU_INTEG_RATE 250). ``gps_rate_hz``: HIL_GPS rate. ``ground_truth``: also send
    HIL_STATE_QUATERNION each frame. ``seed``: sensor noise. ``home``: geodetic position of
    the spawn point (PX4 SITL's default); ``mag_field`` must be given for another home.
    ``spawn_heading_deg``: the heading the vehicle spawns with (deg clockwise from north);
    None: the scenario's start heading, or north without a scenario (90 is how PX4's
    Gazebo worlds, with a zero model pose in their ENU frame, spawn it).
    """

    def __init__(self, platform, *, scenario=None, instance: int = 0,
                 speed_factor: float | None = None, imu_rate_hz: int = 250,
                 gps_rate_hz: float = 10, ground_truth: bool = False, seed: int = 0,
                 host: str = "127.0.0.1", home=frames.PX4_SITL_HOME,
                 mag_field: MagField | None = None, noise: SensorNoise | None = None,
                 diff_pressure: bool = False, physics_hz: int = 1000,
                 spawn_heading_deg: float | None = None):
        if isinstance(instance, bool) or not isinstance(instance, int) or \
                not 0 <= instance <= 65535 - PX4_BASE_PORT:
            raise ValueError(f"instance: {instance!r} must be an integer 0..{65535 - PX4_BASE_PORT}"
                             f" (PX4 connects to port {PX4_BASE_PORT} + instance)")
        if speed_factor is not None and (
                isinstance(speed_factor, bool) or not isinstance(speed_factor, (int, float))
                or not math.isfinite(speed_factor) or speed_factor <= 0):
            raise ValueError(f"speed_factor: {speed_factor!r} must be None (as fast as "
                             f"lockstep allows) or a positive number")
        if isinstance(imu_rate_hz, bool) or not isinstance(imu_rate_hz, int) or imu_rate_hz <= 0 \
                or 1_000_000 % imu_rate_hz:
            raise ValueError(f"imu_rate_hz: {imu_rate_hz!r} must be a positive integer that "
                             f"divides 1,000,000 (a whole number of microseconds per frame)")
        if not isinstance(host, str) or not host:
            raise ValueError(f"host: {host!r} must be an address to listen on")
        self.platform = platform
        self.scenario = scenario
        self.instance = instance
        self.host = host
        self.port = PX4_BASE_PORT + instance
        self.speed_factor = None if speed_factor is None else float(speed_factor)
        self.ground_truth = bool(ground_truth)
        self.vehicle = BridgeVehicle(platform, scenario=scenario, physics_hz=physics_hz,
                                     spawn_yaw=spawn_yaw_from_heading(spawn_heading_deg,
                                                                      scenario))
        self.period_us = 1_000_000 // imu_rate_hz
        if self.period_us % self.vehicle.sim.dt_us:
            raise ValueError(f"imu_rate_hz {imu_rate_hz}: a frame of {self.period_us} us is not"
                             f" a whole number of physics steps of {self.vehicle.sim.dt_us} us "
                             f"(physics_hz {physics_hz})")
        self.motor_map = px4_motor_map(self.vehicle.motor_positions_flu(),
                                       self.vehicle.motor_spins(), platform_name=platform.name,
                                       layout_name=platform.layout)
        self.sensors = SensorSuite(home=home, mag_field=mag_field, noise=noise, seed=seed,
                                   imu_rate_hz=imu_rate_hz, gps_rate_hz=gps_rate_hz,
                                   diff_pressure=diff_pressure)
        self._fields = FIELDS_ACCEL | FIELDS_GYRO | FIELDS_MAG | FIELDS_BARO | (
            FIELDS_DIFF_PRESSURE if diff_pressure else 0)
        self._encoder = mav.MAVLink(None, BRIDGE_SYSID, BRIDGE_COMPID)
        self._parser = self._fresh_parser()
        self._stats = Px4BridgeStats()
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._listener: socket.socket | None = None
        self._client: socket.socket | None = None
        self._thread: threading.Thread | None = None
        self.error: BaseException | None = None
        # per connection
        self._frame_time_us = 0
        self._answered = False
        self._lockstep = False
        self._got_actuators = False
        self._pace_ref: tuple[float, int] | None = None
        self._conn_ref: tuple[float, int] = (0.0, 0)

    # --- public API ---------------------------------------------------------------------
    @property
    def stats(self) -> Px4BridgeStats:
        """A copy of the counters."""
        with self._lock:
            return dataclasses.replace(self._stats)

    def listen(self) -> None:
        """Open the listening socket (run() and start() call this if needed)."""
        if self._listener is not None:
            return
        s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind((self.host, self.port))
            s.listen(2)
        except OSError as exc:
            s.close()
            raise BridgeError(f"PX4 bridge: cannot listen on {self.host}:{self.port} (instance "
                              f"{self.instance}): {exc}") from None
        s.setblocking(False)
        self._listener = s
        log.info("PX4 bridge listening on %s:%d for PX4 instance %d", self.host, self.port,
                 self.instance)

    def run(self) -> None:
        """Serve PX4 connections, one at a time, until :meth:`stop` (blocks)."""
        self.listen()
        pending = None
        try:
            while not self._stop.is_set():
                if pending is None:
                    pending = self._accept()
                    if pending is None:
                        continue
                pending = self._serve(*pending)
        except _Stopped:
            pass
        finally:
            if pending is not None:
                pending[0].close()
            self._close_client()
            if self._listener is not None:
                self._listener.close()
                self._listener = None

    def start(self) -> Px4Bridge:
        """Listen now (errors raise here), then serve in a background thread."""
        if self._thread is not None:
            raise BridgeError("PX4 bridge: already started")
        self._stop.clear()
        self.listen()

        def target():
            try:
                self.run()
            except BaseException as exc:  # noqa: BLE001 - handed to stop()/the caller
                self.error = exc
                log.exception("PX4 bridge stopped by an error")

        self._thread = threading.Thread(target=target, name=f"px4-bridge-{self.instance}",
                                        daemon=True)
        self._thread.start()
        return self

    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def stop(self, timeout: float = 10.0) -> None:
        """Stop serving (from any thread); joins the background thread of start()."""
        self._stop.set()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout)
            if self._thread.is_alive():
                raise BridgeError(f"PX4 bridge: the serving thread did not stop within "
                                  f"{timeout} s")
            self._thread = None
        if self.error is not None:
            raise BridgeError(f"PX4 bridge failed: {self.error!r}") from self.error

    def __enter__(self) -> Px4Bridge:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()

    # --- connections --------------------------------------------------------------------
    def _accept(self):
        r, _, _ = select.select([self._listener], [], [], _POLL_S)
        if not r:
            return None
        try:
            return self._listener.accept()
        except (BlockingIOError, InterruptedError):
            return None

    def _serve(self, sock: socket.socket, addr):
        """Fly one PX4 connection; returns the next (sock, addr) if one replaced it."""
        self._client = sock
        try:
            sock.setblocking(False)
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        except OSError as exc:
            log.info("PX4 connection from %s:%d gone at once (%s)", addr[0], addr[1], exc)
            self._close_client()
            return None
        self.vehicle.reset()
        self.sensors.reset()
        self._parser = self._fresh_parser()
        self._answered = False
        self._lockstep = False
        self._got_actuators = False
        now = time.monotonic()
        self._pace_ref = (now, self.vehicle.time_us)
        self._conn_ref = (now, self.vehicle.time_us)
        with self._lock:
            self._stats.connections += 1
            self._stats.connected = True
            self._stats.lockstep = False
            self._stats.px4_armed = False
            self._stats.crash = None
        log.info("PX4 connected from %s:%d (connection %d); vehicle reset to its spawn point",
                 addr[0], addr[1], self._stats.connections)
        try:
            while True:
                if self._stop.is_set():
                    raise _Stopped
                self._advance()
                self._send_frame()
                if self._lockstep:
                    self._await_answer(None)
                    if self.speed_factor is not None:
                        self._pace_wait()
                else:
                    self._await_answer(self._pace_deadline())
        except _Disconnected as exc:
            log.info("PX4 disconnected (%s); waiting for the next connection", exc)
            return None
        except _Replaced as new:
            log.info("a new PX4 connected from %s:%d; dropping the old connection",
                     new.addr[0], new.addr[1])
            return new.sock, new.addr
        finally:
            self._close_client()
            with self._lock:
                self._stats.connected = False

    def _close_client(self) -> None:
        if self._client is not None:
            try:
                self._client.close()
            except OSError:
                pass
            self._client = None

    # --- one frame ----------------------------------------------------------------------
    def _advance(self) -> None:
        """Physics by one IMU period with the current motor command."""
        self.vehicle.step_us(self.period_us)
        crash = self.vehicle.crash
        with self._lock:
            self._stats.steps += 1
            self._stats.sim_time_us = self.vehicle.time_us
            wall0, sim0 = self._conn_ref
            elapsed = time.monotonic() - wall0
            if elapsed > 0:
                self._stats.achieved_speed_factor = (self.vehicle.time_us - sim0) / 1e6 / elapsed
            if crash is not None and self._stats.crash is None:
                self._stats.crash = crash
                log.warning("the vehicle crashed into %s at %.2f m/s (t = %.3f s): motors off",
                            crash.what, crash.speed_m_s, crash.time_us / 1e6)

    def _send_frame(self) -> None:
        t = self.vehicle.time_us
        self._frame_time_us = t
        v = self.vehicle
        s = self.sensors.hil_sensor(v, t)
        out = [mav.MAVLink_hil_sensor_message(
            t, *s.accel_frd, *s.gyro_frd, *s.mag_frd, s.abs_pressure_hpa, s.diff_pressure_hpa,
            s.pressure_alt_m, s.temperature_c, self._fields, 0).pack(self._encoder)]
        gps = self.sensors.gps(v, t) if self.sensors.gps_due(t) else None
        if gps is not None:
            out.append(mav.MAVLink_hil_gps_message(
                t, gps.fix_type, gps.lat_e7, gps.lon_e7, gps.alt_mm, gps.eph_cm, gps.epv_cm,
                gps.vel_cm_s, gps.vn_cm_s, gps.ve_cm_s, gps.vd_cm_s, gps.cog_cdeg,
                gps.satellites, 0, 0).pack(self._encoder))
        if self.ground_truth:
            out.append(self._ground_truth_message(t).pack(self._encoder))
        with self._lock:  # counted before sending: a peer that has the frame sees it counted
            self._stats.sensor_frames += 1
            if not self._got_actuators:
                self._stats.boot_frames += 1
            if gps is not None:
                self._stats.gps_frames += 1
            if self.ground_truth:
                self._stats.ground_truth_frames += 1
        data = b"".join(out)
        try:
            sent = self._client.send(data)
        except (BlockingIOError, InterruptedError):
            sent = 0
        except OSError as exc:
            raise _Disconnected(f"send failed: {exc}") from None
        if sent < len(data):
            self._send_blocking(data[sent:])

    def _send_blocking(self, data: bytes) -> None:
        """The rare send that meets a full socket buffer: finish it, watching for stop()."""
        view = memoryview(data)
        while view:
            if self._stop.is_set():
                raise _Stopped
            _, w, _ = select.select([], [self._client], [], _POLL_S)
            if not w:
                continue
            try:
                view = view[self._client.send(view):]
            except (BlockingIOError, InterruptedError):
                continue
            except OSError as exc:
                raise _Disconnected(f"send failed: {exc}") from None

    def _ground_truth_message(self, t: int):
        v = self.vehicle
        p_ned = v.position_ned()
        lat, lon, alt = self.sensors.home.to_global(frames.ned_to_enu(p_ned))
        vel = v.velocity_ned()
        acc_mg = np.clip(np.rint(v.accel_frd() / G * 1000.0), -32768, 32767).astype(int)
        vel_cm = np.clip(np.rint(vel * 100.0), -32768, 32767).astype(int)
        speed = int(min(65535, round(float(np.linalg.norm(vel)) * 100.0)))
        q = v.q_ned_frd()
        w = v.gyro_frd()
        return mav.MAVLink_hil_state_quaternion_message(
            t, [float(c) for c in q], float(w[0]), float(w[1]), float(w[2]),
            int(round(lat * 1e7)), int(round(lon * 1e7)), int(round(alt * 1000.0)),
            int(vel_cm[0]), int(vel_cm[1]), int(vel_cm[2]), speed, speed,
            int(acc_mg[0]), int(acc_mg[1]), int(acc_mg[2]))

    # --- waiting and pacing -------------------------------------------------------------
    def _await_answer(self, deadline: float | None) -> bool:
        """Read PX4's messages until an actuator message answers the current frame (True) or
        the wall-clock deadline passes (False); None waits as long as it takes."""
        while True:
            if self._answered:
                self._answered = False
                return True
            if self._stop.is_set():
                raise _Stopped
            if self._lockstep:  # PX4 started lockstep during a boot frame: it answers this one
                deadline = None
            timeout = _POLL_S
            if deadline is not None:
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                timeout = min(timeout, left)
            r, _, _ = select.select([self._client, self._listener], [], [], timeout)
            if self._listener in r:
                try:
                    new_sock, addr = self._listener.accept()
                except (BlockingIOError, InterruptedError):
                    new_sock = None
                if new_sock is not None:
                    raise _Replaced(new_sock, addr)
            if self._client in r:
                try:
                    data = self._client.recv(65536)
                except (BlockingIOError, InterruptedError):
                    continue
                except OSError as exc:
                    raise _Disconnected(str(exc)) from None
                if not data:
                    raise _Disconnected("end of stream")
                self._on_bytes(data)

    def _pace_target(self) -> float:
        """Wall time at which the current simulated time is due (speed factor, 1 if None)."""
        speed = self.speed_factor or 1.0
        now = time.monotonic()
        wall0, sim0 = self._pace_ref
        target = wall0 + (self.vehicle.time_us - sim0) / 1e6 / speed
        if now - target > _PACE_SLACK_S:  # fell behind (PX4 paused, slow CPU): no burst
            self._pace_ref = (now, self.vehicle.time_us)
            target = now
        return target

    def _pace_deadline(self) -> float:
        """Deadline of a boot/free-running frame: when the next frame's time is due."""
        return self._pace_target() + self.period_us / 1e6 / (self.speed_factor or 1.0)

    def _pace_wait(self) -> None:
        """Lockstep at a speed factor: hold until the next frame is due."""
        left = self._pace_deadline() - time.monotonic()
        if left > 0 and self._stop.wait(left):
            raise _Stopped

    # --- incoming -----------------------------------------------------------------------
    @staticmethod
    def _fresh_parser() -> mav.MAVLink:
        p = mav.MAVLink(None, 0, 0)
        p.robust_parsing = True
        return p

    def _bad(self, what: str) -> None:
        with self._lock:
            self._stats.bad_packets += 1
            n = self._stats.bad_packets
        if n <= 10 or n % 100 == 0:
            log.warning("PX4 link: %s (bad packet #%d, ignored)", what, n)

    def _on_bytes(self, data: bytes) -> None:
        try:
            msgs = self._parser.parse_buffer(data) or []
        except Exception as exc:  # noqa: BLE001 - pymavlink raises on some corrupt input
            self._bad(f"unparseable bytes ({exc})")
            self._parser = self._fresh_parser()
            return
        for m in msgs:
            kind = m.get_type()
            if kind == "BAD_DATA":
                self._bad(str(getattr(m, "reason", "bad data")))
            elif kind == "HIL_ACTUATOR_CONTROLS":
                self._on_actuators(m)
            elif kind in PX4_OTHER_MESSAGES:
                with self._lock:
                    self._stats.other_messages += 1
                if kind == "COMMAND_LONG" and m.command == mav.MAV_CMD_SET_MESSAGE_INTERVAL \
                        and int(m.param1) == mav.MAVLINK_MSG_ID_HIL_STATE_QUATERNION:
                    log.debug("PX4 asks for HIL_STATE_QUATERNION every %.0f us (%s)", m.param2,
                              "sent each frame" if self.ground_truth else "ground_truth is off")
            else:
                with self._lock:
                    self._stats.unexpected_messages += 1
                    n = self._stats.unexpected_messages
                if n <= 10 or n % 100 == 0:
                    log.warning("PX4 link: unexpected %s (#%d, ignored)", kind, n)

    def _on_actuators(self, m) -> None:
        controls = np.asarray(m.controls[:len(self.motor_map)], dtype=float)
        if not np.all(np.isfinite(controls)):
            self._bad(f"non-finite motor outputs {controls.tolist()} (taken as 0)")
            controls = np.where(np.isfinite(controls), controls, 0.0)
        u = np.zeros(len(self.motor_map))
        u[list(self.motor_map)] = controls
        self.vehicle.set_motors(u)  # clips to 0..1, NaN -> 0; ignored after a crash
        lockstep = bool(m.flags & LOCKSTEP_FLAG)
        stale = m.time_usec != 0 and m.time_usec < self._frame_time_us
        with self._lock:
            self._stats.actuator_messages += 1
            self._stats.lockstep = lockstep
            self._stats.px4_armed = bool(m.mode & ARMED_FLAG)
            if stale:
                self._stats.stale_actuator_messages += 1
        if not self._got_actuators:
            self._got_actuators = True
            log.info("first actuator message from PX4 (%s) after %d boot frames",
                     "lockstep" if lockstep else "no lockstep: free-running at the wall clock",
                     self._stats.boot_frames)
        if lockstep != self._lockstep:
            self._pace_ref = (time.monotonic(), self.vehicle.time_us)
        self._lockstep = lockstep
        if lockstep and not stale:
            self._answered = True


# --- command line ---------------------------------------------------------------------------
from ft_sitl.scenarios.io import scenario_from_spec  # noqa: E402,F401 - re-exported


def run_px4_bridge(platform_name: str, scenario=None, *, instance: int = 0,
                   speed_factor: float | None = None, ground_truth: bool = False,
                   seed: int = 0, host: str = "127.0.0.1", platform_files=(),
                   duration_s: float | None = None, status_every_s: float = 10.0,
                   echo: Callable[[str], None] = print,
                   wind: dict | None = None,
                   actuators: dict | None = None,
                   spawn_heading_deg: float | None = None) -> Px4BridgeStats:
    """Serve PX4 SITL instance ``instance`` until Ctrl-C (or ``duration_s`` of wall time).

    ``platform_name``: a catalog platform, or one from ``platform_files``; ``scenario``:
    None, a Scenario, ``FAMILY:INDEX[:SEED]`` or a spec file. Prints a banner, a status
    line every ``status_every_s`` and the final counters through ``echo``; returns them.
    Raises ValueError for a bad platform/scenario/option, BridgeError if it cannot listen.
    ``wind``: wind settings (ft_sitl.physics.wind) the vehicle flies in, turbulence seeded
    by ``seed``; None: calm air. ``actuators``: imperfect actuators
    (ft_sitl.physics.actuators) between PX4's motor outputs and the rotors; None: as built.
    ``spawn_heading_deg``: the spawn heading (deg, 0 north); None: the scenario's, or north.
    """

    platform = PlatformRegistry(platform_files).get(platform_name)
    bridge = Px4Bridge(platform, scenario=scenario_from_spec(scenario), instance=instance,
                       speed_factor=speed_factor, ground_truth=ground_truth, seed=seed,
                       host=host, spawn_heading_deg=spawn_heading_deg)
    bridge.vehicle.sim.set_wind(0, wind, seed=seed)
    bridge.vehicle.sim.set_actuators(0, actuators, seed=seed)
    bridge.start()
    sc = bridge.scenario
    echo(f"PX4 bridge: {platform.name} ({platform.layout}, PX4 motor i -> our rotor "
         f"{[j + 1 for j in bridge.motor_map]}), "
         f"{'scenario ' + sc.name if sc is not None else 'no scenario'}, spawn heading "
         f"{math.degrees(frames.yaw_enu_to_ned(bridge.vehicle.spawn_yaw)) % 360.0:.1f} deg, "
         f"listening on {host}:{bridge.port}")
    params = " ".join(f"PX4_PARAM_{k}={v:g}"
                      for k, v in px4_parameters(platform, bridge.motor_map).items())
    echo(f"  start PX4 (lockstep at {1e6 / bridge.period_us:.0f} Hz, "
         f"{'as fast as PX4 answers' if speed_factor is None else f'speed {speed_factor:g}x'})"
         f" from PX4-Autopilot, with this platform's geometry and thrust model:")
    echo(f"    {params} PX4_SIM_MODEL=none_iris build/px4_sitl_default/bin/px4 -i {instance}")
    t0 = time.monotonic()
    next_status = t0 + status_every_s
    try:
        while bridge.running:
            now = time.monotonic()
            if duration_s is not None and now - t0 >= duration_s:
                break
            if now >= next_status:
                s = bridge.stats
                sf = "-" if s.achieved_speed_factor is None else f"{s.achieved_speed_factor:.2f}"
                echo(f"  t_sim {s.sim_time_us / 1e6:9.2f} s  "
                     f"{'connected' if s.connected else 'waiting for PX4'}  "
                     f"{'armed' if s.px4_armed else 'disarmed'}  speed {sf}x  "
                     f"frames {s.sensor_frames}  bad {s.bad_packets}"
                     + (f"  CRASHED into {s.crash.what}" if s.crash else ""))
                next_status = now + status_every_s
            time.sleep(0.2)
    except KeyboardInterrupt:
        pass
    finally:
        bridge.stop()
    s = bridge.stats
    echo(f"PX4 bridge stopped: {s.connections} connection(s), {s.steps} steps "
         f"({s.sim_time_us / 1e6:.2f} s simulated), {s.actuator_messages} actuator messages, "
         f"{s.bad_packets} bad packets, {s.unexpected_messages} unexpected messages")
    return s
