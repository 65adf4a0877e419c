"""ArduPilot in the loop: ArduPilot's SITL (``--model JSON``) flies our vehicle over UDP.

ArduPilot's JSON simulator backend (``libraries/SITL/SIM_JSON.cpp``) sends one binary servo
packet per physics frame to UDP port 9002 and blocks until the simulator answers with one
line of JSON holding the vehicle state. :class:`ArduPilotBridge` is that simulator:

servo packet in (little-endian; ``SIM_JSON.h``, ``servo_packet_16`` / ``servo_packet_32``)
    ``<HHI16H``: magic 18458, frame_rate (Hz), frame_count, 16 PWM widths (µs), or
    ``<HHI32H``: magic 29569, the same with 32 widths (``SERVO_32_ENABLE = 1``);
    anything else is counted as bad, logged, and not answered (never fatal).
lockstep
    a new frame_count: map the PWM widths from ArduPilot's motor order to ours
    (:func:`motor_mapping`), ``1000 µs -> 0`` .. ``2000 µs -> 1`` (clipped), set the motors,
    advance the plant by ``1 / frame_rate`` seconds, answer with the state;
    the same frame_count again (ArduPilot did not get or could not use our answer and
    re-sent its packet): resend the previous answer byte for byte, do not step;
    a smaller frame_count: ArduPilot restarted, so the vehicle goes back to its spawn
    point at rest and the clock back to 0.
state out (``SIM_JSON.cpp``, ``JSON::recv_fdm`` / ``JSON::parse_sensors``)
    ``"\\n" + {"timestamp":t,"imu":{"gyro":[p,q,r],"accel_body":[x,y,z]},
    "position":[n,e,d],"quaternion":[w,x,y,z],"velocity":[n,e,d]} + "\\n"``: the clock
    in seconds since the (re)start, body rates (rad/s, FRD), specific force (m/s^2, FRD: at
    rest -g on z), position relative to the spawn point = ArduPilot's home (m, NED),
    velocity (m/s, NED), attitude as the NED <- FRD quaternion. Compact separators: the
    parser skips exactly ``"`` and ``:`` after a key and then wants the ``[`` at once.

The answer goes to the address the packet came from. The reported timestamp is exactly
``k / frame_rate`` after k frames (ArduPilot derives its own clock and its frame rate from
the differences); the plant moves on its own grid of whole physics steps (``physics_hz``)
to the step nearest that time, within half a step (125 µs at the default 4 kHz) when
``1e6 / frame_rate`` is not a whole number of steps (ArduPilot's default 1200 Hz).

Reference: docs/autopilot-in-the-loop.md (ArduPilot section).
"""

from __future__ import annotations

import json
import logging
import math
import socket
import struct
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ft_sitl import frames
from ft_sitl.bridge import ARDUPILOT_DEFAULT_PORT
from ft_sitl.bridge.ardupilot_frames import motor_mapping_for
from ft_sitl.bridge.ardupilot_params import ardupilot_params
from ft_sitl.bridge.vehicle import BridgeVehicle, spawn_yaw_from_heading
from ft_sitl.physics.catalog import PlatformRegistry
from ft_sitl.physics.platform import Platform
from ft_sitl.scenarios.io import scenario_from_spec

log = logging.getLogger(__name__)

DEFAULT_PORT = ARDUPILOT_DEFAULT_PORT
SERVO_MAGIC_16 = 18458
SERVO_MAGIC_32 = 29569
_SERVO_16 = struct.Struct("<HHI16H")
_SERVO_32 = struct.Struct("<HHI32H")
_MAGIC = struct.Struct("<H")
DEFAULT_PHYSICS_HZ = 4000


# --- servo packets ---------------------------------------------------------------------
class ServoPacketError(ValueError):
    """A datagram that is not one of ArduPilot's JSON servo packets."""


@dataclass(frozen=True)
class ServoPacket:
    frame_rate_hz: int
    frame_count: int
    pwm_us: tuple[int, ...]  # 16 or 32 widths, servo channel 1 first


def parse_servo_packet(data: bytes) -> ServoPacket:
    """Decode one servo packet (either layout); :class:`ServoPacketError` says what is wrong."""
    if len(data) < _MAGIC.size:
        raise ServoPacketError(f"{len(data)}-byte datagram: too short to hold the 2-byte magic")
    (magic,) = _MAGIC.unpack_from(data)
    if magic == SERVO_MAGIC_16:
        layout = _SERVO_16
    elif magic == SERVO_MAGIC_32:
        layout = _SERVO_32
    else:
        raise ServoPacketError(
            f"magic {magic} is neither {SERVO_MAGIC_16} (16 channels) nor "
            f"{SERVO_MAGIC_32} (32 channels)"
        )
    if len(data) != layout.size:
        raise ServoPacketError(
            f"magic {magic} announces a {layout.size}-byte packet, got {len(data)} bytes"
        )
    _, rate, count, *pwm = layout.unpack(data)
    if rate == 0:
        raise ServoPacketError("frame_rate 0 Hz: no time step to take")
    return ServoPacket(rate, count, tuple(pwm))


def _vec(v) -> list[float]:
    return [float(x) for x in v]


_ENCODER = json.JSONEncoder(separators=(",", ":"), allow_nan=False)


def state_message(timestamp_s: float, gyro_frd, accel_frd, position_ned, velocity_ned,
                  q_ned_frd) -> bytes:
    """One answer: a newline, the JSON object with compact separators, a newline.

    SIM_JSON's parser finds each key with strstr, skips the key's closing quote and the
    colon, and reads vectors with sscanf("[%f, %f, %f]"): no space may follow the colon;
    the space after each comma is optional (a space in a scanf format matches none too).
    It takes the text between the last two newlines, so both are needed.
    """
    obj = {
        "timestamp": float(timestamp_s),
        "imu": {"gyro": _vec(gyro_frd), "accel_body": _vec(accel_frd)},
        "position": _vec(position_ned),
        "quaternion": _vec(q_ned_frd),
        "velocity": _vec(velocity_ned),
    }
    try:
        text = _ENCODER.encode(obj)
    except ValueError:
        raise ValueError(f"vehicle state is not finite, not sending it to ArduPilot: {obj}"
                         ) from None
    return ("\n" + text + "\n").encode("ascii")


# --- the bridge ---------------------------------------------------------------------------
@dataclass
class BridgeCounters:
    packets: int = 0  # datagrams received
    frames: int = 0  # new frames: motors set, plant stepped, state sent
    repeats: int = 0  # repeated frame_count: previous answer resent, no step
    restarts: int = 0  # frame_count went down: vehicle reset
    skipped_frames: int = 0  # frame_count jumped by more than one (frames never received)
    bad_packets: int = 0  # not a servo packet: counted, logged, not answered
    replies: int = 0  # answers sent
    send_errors: int = 0  # answers the socket refused
    frames_without_step: int = 0  # frame shorter than half a physics step

    def as_dict(self) -> dict[str, int]:
        return dict(self.__dict__)


class ArduPilotBridge:
    """Our vehicle as ArduPilot's JSON simulator, lockstepped by ArduPilot's servo packets.

    Nothing is opened in the constructor: :meth:`open` binds the UDP socket (``port=0``
    picks a free port, see :attr:`address`), :meth:`run` serves until :meth:`stop`.
    :meth:`handle` is the transport-free core (datagram in, answer out).

    speed_factor: ``None`` answers as soon as the plant has stepped (ArduPilot paces itself
    with its ``--speedup``); a number holds each answer back until simulated time is
    ``speed_factor`` times the wall time since the first frame.
    accel_noise_m_s2: standard deviation of white noise added to accel_body (drawn from
    ``numpy.random.default_rng(seed)``); 0 sends the exact specific force, which is the
    default because ArduPilot's own SITL IMU driver already adds noise to it.
    spawn_heading_deg: the heading the vehicle spawns with (deg clockwise from north; give
    ArduPilot's ``--home`` the same heading); None: the scenario's start heading, or north
    without a scenario.
    """

    def __init__(self, platform, *, scenario=None, port: int = DEFAULT_PORT,
                 host: str = "127.0.0.1", speed_factor: float | None = None, seed: int = 0,
                 physics_hz: int = DEFAULT_PHYSICS_HZ, accel_noise_m_s2: float = 0.0,
                 spawn_heading_deg: float | None = None):
        if speed_factor is not None and not (math.isfinite(speed_factor) and speed_factor > 0):
            raise ValueError(f"speed_factor: {speed_factor!r} must be a positive number or "
                             f"None (lockstep as fast as ArduPilot sends)")
        if not (isinstance(port, int) and 0 <= port <= 65535):
            raise ValueError(f"port: {port!r} must be an integer within 0..65535")
        if not (math.isfinite(accel_noise_m_s2) and accel_noise_m_s2 >= 0.0):
            raise ValueError(f"accel_noise_m_s2: {accel_noise_m_s2!r} must be >= 0")
        self.platform = platform
        self.mapping = motor_mapping_for(platform)  # refuses a layout ArduPilot cannot fly
        self.vehicle = BridgeVehicle(platform, scenario=scenario, physics_hz=physics_hz,
                                     spawn_yaw=spawn_yaw_from_heading(spawn_heading_deg,
                                                                      scenario))
        self.physics_hz = physics_hz
        self.host = host
        self.port = port
        self.speed_factor = speed_factor
        self.accel_noise_m_s2 = float(accel_noise_m_s2)
        self._rng = np.random.default_rng(seed)
        self.counters = BridgeCounters()
        self._sock: socket.socket | None = None
        self._stop = threading.Event()
        self._crash_reported = False
        self._restart_clock()

    # --- lockstep core (no sockets) ------------------------------------------------------
    def _restart_clock(self) -> None:
        self._last_count: int | None = None
        self._last_reply: bytes | None = None
        self._rate_hz: int | None = None
        self._t_base_s = 0.0  # time at the last frame-rate change
        self._n_at_rate = 0  # frames since then
        self._steps = 0  # physics steps since the (re)start
        self._timestamp_s = 0.0
        self._pace_origin: tuple[float, float] | None = None  # (wall s, simulated s)
        self._last_motor_pwm: tuple[int, ...] | None = None  # what the motors are set to

    @property
    def time_s(self) -> float:
        """The simulated time last sent to ArduPilot (s since its (re)start)."""
        return self._timestamp_s

    @property
    def frame_rate_hz(self) -> int | None:
        return self._rate_hz

    def handle(self, data: bytes, sender=None) -> bytes | None:
        """One datagram from ArduPilot -> the answer to send back (None: not answered).

        sender: the datagram's source address, only for the log of bad packets.
        """
        c = self.counters
        c.packets += 1
        try:
            pkt = parse_servo_packet(data)
        except ServoPacketError as exc:
            c.bad_packets += 1
            self._log_bad(str(exc), sender)
            return None
        last = self._last_count
        if last is not None:
            if pkt.frame_count == last:
                c.repeats += 1
                c.replies += 1
                return self._last_reply
            if pkt.frame_count < last:
                c.restarts += 1
                log.info("ArduPilot restarted (frame_count %d after %d): vehicle back at its "
                         "spawn point, clock at 0", pkt.frame_count, last)
                self.vehicle.reset()
                self._crash_reported = False
                self._restart_clock()
            elif pkt.frame_count > last + 1:
                c.skipped_frames += pkt.frame_count - last - 1
        self._last_count = pkt.frame_count
        self._last_reply = self._advance(pkt)
        c.frames += 1
        c.replies += 1
        return self._last_reply

    def _advance(self, pkt: ServoPacket) -> bytes:
        v = self.vehicle
        motors = pkt.pwm_us[: self.mapping.n_motors]
        if motors != self._last_motor_pwm:  # ArduPilot's outputs change at its loop rate
            v.set_motors(self.mapping.commands(motors))
            self._last_motor_pwm = motors
        if pkt.frame_rate_hz != self._rate_hz:
            if self._rate_hz is not None:
                self._t_base_s += self._n_at_rate / self._rate_hz
            self._rate_hz = pkt.frame_rate_hz
            self._n_at_rate = 0
        self._n_at_rate += 1
        t = self._t_base_s + self._n_at_rate / self._rate_hz
        n = math.floor(t * self.physics_hz + 0.5) - self._steps
        if n > 0:
            v.step_us(n * v.sim.dt_us)
            self._steps += n
        else:
            self.counters.frames_without_step += 1
            if self.counters.frames_without_step == 1:
                log.warning("frame rate %d Hz is above the physics rate %d Hz: some frames "
                            "do not move the plant (raise physics_hz)", pkt.frame_rate_hz,
                            self.physics_hz)
        self._timestamp_s = t
        if v.crash is not None and not self._crash_reported:
            self._crash_reported = True
            log.warning("crash at t=%.3f s: %s at %.2f m/s; motors off until ArduPilot "
                        "restarts", t, v.crash.what, v.crash.speed_m_s)
        accel = v.accel_frd()
        if self.accel_noise_m_s2 > 0.0:
            accel = accel + self._rng.normal(0.0, self.accel_noise_m_s2, 3)
        return state_message(t, v.gyro_frd(), accel, v.position_ned(), v.velocity_ned(),
                             v.q_ned_frd())

    def _log_bad(self, why: str, sender) -> None:
        n = self.counters.bad_packets
        if n <= 10 or n % 1000 == 0:
            source = f" from {sender[0]}:{sender[1]}" if sender else ""
            log.warning("ignored datagram %d%s (bad packet %d): %s", self.counters.packets,
                        source, n, why)

    # --- UDP -----------------------------------------------------------------------------
    def open(self) -> tuple[str, int]:
        """Bind the UDP socket; returns the bound (host, port)."""
        if self._sock is not None:
            return self.address
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            sock.bind((self.host, self.port))
        except OSError as exc:
            sock.close()
            raise OSError(f"cannot listen for ArduPilot's servo packets on UDP "
                          f"{self.host}:{self.port}: {exc.strerror or exc} (another "
                          f"simulator on that port?)") from exc
        sock.settimeout(0.1)  # how often run() looks at stop()
        self._sock = sock
        self._stop.clear()
        return self.address

    @property
    def address(self) -> tuple[str, int]:
        if self._sock is None:
            raise RuntimeError("the bridge is not open: call open() or run() first")
        host, port = self._sock.getsockname()[:2]
        return host, port

    def close(self) -> None:
        if self._sock is not None:
            self._sock.close()
            self._sock = None

    def stop(self) -> None:
        """Ask run() to return (safe from another thread or a signal handler)."""
        self._stop.set()

    def run(self) -> BridgeCounters:
        """Serve ArduPilot until stop(); opens the socket if needed. Returns the counters.

        A stop() that comes before run() starts (but after open()) is kept: run() returns
        at once.
        """
        self.open()
        sock = self._sock
        while not self._stop.is_set():
            try:
                data, addr = sock.recvfrom(65536)
            except TimeoutError:
                continue
            except (ConnectionRefusedError, ConnectionResetError):
                continue  # an ICMP error for an earlier answer: ArduPilot went away
            reply = self.handle(data, addr)
            if reply is None:
                continue
            self._pace()
            try:
                sock.sendto(reply, addr)
            except OSError as exc:
                self.counters.send_errors += 1
                if self.counters.send_errors <= 10:
                    log.warning("could not answer %s:%d: %s", addr[0], addr[1], exc)
        return self.counters

    def _pace(self) -> None:
        if self.speed_factor is None:
            return
        now = time.monotonic()
        if self._pace_origin is None:
            self._pace_origin = (now, self._timestamp_s)
            return
        wall0, sim0 = self._pace_origin
        ahead = wall0 + (self._timestamp_s - sim0) / self.speed_factor - now
        if ahead > 0.0:
            time.sleep(ahead)

    def achieved_speed_factor(self) -> float | None:
        """Simulated seconds per wall second since pacing started (speed_factor runs only)."""
        if self._pace_origin is None:
            return None
        wall = time.monotonic() - self._pace_origin[0]
        return (self._timestamp_s - self._pace_origin[1]) / wall if wall > 0 else None

    def __enter__(self) -> ArduPilotBridge:
        self.open()
        return self

    def __exit__(self, *exc) -> None:
        self.stop()
        self.close()


# --- the command's entry point -----------------------------------------------------------
def run_ardupilot_bridge(platform_name, scenario_spec=None, port: int = DEFAULT_PORT,
                         speed_factor: float | None = None, *, host: str = "127.0.0.1",
                         seed: int = 0, physics_hz: int = DEFAULT_PHYSICS_HZ,
                         accel_noise_m_s2: float = 0.0, platform_files=(),
                         params_path=None, echo=print, on_start=None,
                         wind: dict | None = None, actuators: dict | None = None,
                         spawn_heading_deg: float | None = None) -> dict:
    """Serve one ArduPilot SITL until Ctrl-C; returns a summary (counters, time, crash).

    platform_name: a catalog or user-file name (``platform_files``), or a Platform.
    scenario_spec: None (open ground), a Scenario, ``FAMILY:INDEX[:SEED]`` or a spec file.
    params_path: where to write the ArduCopter parameter file for the platform (None: not
    written; :func:`ft_sitl.bridge.ardupilot_params.ardupilot_params` returns the text).
    echo: where the start-up lines go (``print``; ``None`` for silence).
    on_start: called with the open :class:`ArduPilotBridge` before serving (e.g. to keep a
    handle for ``stop()`` from a signal handler or another thread).
    wind: wind settings (ft_sitl.physics.wind) the vehicle flies in, turbulence seeded by
    ``seed``; None: calm air. actuators: imperfect actuators (ft_sitl.physics.actuators:
    ArduPilot's motor outputs are degraded, lagged, noisy or cut as in a campaign); None:
    as built. A bad setting raises ValueError (SchemaError). spawn_heading_deg: the spawn
    heading (deg, 0 north); None: the scenario's start heading, or north.
    """

    platform = (platform_name if isinstance(platform_name, Platform)
                else PlatformRegistry(platform_files).get(platform_name))

    scenario = scenario_from_spec(scenario_spec)
    bridge = ArduPilotBridge(platform, scenario=scenario, port=port, host=host,
                             speed_factor=speed_factor, seed=seed, physics_hz=physics_hz,
                             accel_noise_m_s2=accel_noise_m_s2,
                             spawn_heading_deg=spawn_heading_deg)
    bridge.vehicle.sim.set_wind(0, wind, seed=seed)
    bridge.vehicle.sim.set_actuators(0, actuators, seed=seed)
    if params_path is not None:

        Path(params_path).write_text(ardupilot_params(platform), encoding="utf-8")
    say = echo or (lambda *a, **k: None)
    bound = bridge.open()
    try:
        m = bridge.mapping
        heading = math.degrees(frames.yaw_enu_to_ned(bridge.vehicle.spawn_yaw)) % 360.0
        say(f"ArduPilot JSON bridge: {platform.name} as ArduCopter {m.frame.name} "
            f"(FRAME_CLASS {m.frame.frame_class}, FRAME_TYPE {m.frame.frame_type}) on UDP "
            f"{bound[0]}:{bound[1]}" + (f", scenario {scenario.name}" if scenario else "")
            + f", spawn heading {heading:.1f} deg", flush=True)
        say("ArduPilot motor -> our rotor: " + ", ".join(
            f"{j + 1}->{i + 1}" for j, i in enumerate(m.ours_for_ardupilot)), flush=True)
        if params_path is not None:
            say(f"parameters written to {params_path}", flush=True)
        say(f"start ArduCopter with: arducopter --model JSON:{bound[0]} --serial0 tcp:0 "
            f"--defaults {params_path or 'PARAMS.parm'} --home LAT,LON,ALT,{heading:.0f} "
            f"(--sim-port-out {bound[1]} if not 9002); Ctrl-C stops", flush=True)
        if on_start is not None:
            on_start(bridge)
        try:
            bridge.run()
        except KeyboardInterrupt:
            pass
    finally:
        bridge.close()
    v = bridge.vehicle
    return {
        "platform": platform.name,
        "frame": bridge.mapping.frame.name,
        "address": list(bound),
        "sim_time_s": bridge.time_s,
        "frame_rate_hz": bridge.frame_rate_hz,
        "achieved_speed_factor": bridge.achieved_speed_factor(),
        "counters": bridge.counters.as_dict(),
        "crash": None if v.crash is None else {"time_us": v.crash.time_us, "what": v.crash.what,
                                               "speed_m_s": v.crash.speed_m_s},
    }
