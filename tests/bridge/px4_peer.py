"""PX4's side of the simulator link, written from PX4's simulator_mavlink for the tests.

What PX4 SITL does on the wire (src/modules/simulation/simulator_mavlink/
SimulatorMavlink.cpp), and what :class:`Px4Peer` does the same way:

- it connects as a TCP client to 4560 + instance with TCP_NODELAY;
- its sender thread first sends a HEARTBEAT (autopilot 12, base_mode 0 while disarmed),
  its receiver thread a COMMAND_LONG SET_MESSAGE_INTERVAL(HIL_STATE_QUATERNION, 5000 us);
- it parses MAVLink 2 (pymavlink here) and answers each HIL_SENSOR with one
  HIL_ACTUATOR_CONTROLS: time_usec = its clock = the last HIL_SENSOR's time_usec,
  controls[16] (motors 0..1, zeros while disarmed), mode = MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
  | MAV_MODE_FLAG_SAFETY_ARMED when armed, flags = HIL_ACTUATOR_CONTROLS_FLAGS_LOCKSTEP;
  sysid 1 + instance (MAV_SYS_ID), compid 1.

Reads have a generous time limit so a broken bridge fails the test instead of hanging it;
no test asserts how long anything took.
"""

from __future__ import annotations

import select
import socket
import time
from dataclasses import dataclass, field

from pymavlink.dialects.v20 import common as mav

READ_LIMIT_S = 60.0


@dataclass
class Frame:
    """One lockstep frame as PX4 receives it: the HIL_SENSOR and what came with it."""

    sensor: object
    gps: object | None = None
    state: object | None = None
    others: list = field(default_factory=list)

    @property
    def time_usec(self) -> int:
        return int(self.sensor.time_usec)


class Px4Peer:
    def __init__(self, port: int, *, instance: int = 0, expect_ground_truth: bool = False,
                 host: str = "127.0.0.1"):
        self.port = port
        self.host = host
        self.sysid = 1 + instance
        self.expect_ground_truth = expect_ground_truth
        self.sock: socket.socket | None = None
        self._parser = mav.MAVLink(None, 0, 0)
        self._parser.robust_parsing = True
        self._encoder = mav.MAVLink(None, self.sysid, 1)
        self._pending: list = []  # parsed, not yet handed out
        self.last_time_usec = 0
        self.frames_received = 0
        self.closed_by_bridge = False

    # --- connection, as PX4 does it ---------------------------------------------------------
    def connect(self) -> Px4Peer:
        deadline = time.monotonic() + READ_LIMIT_S
        while True:
            try:
                s = socket.create_connection((self.host, self.port), timeout=5.0)
                break
            except OSError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.01)
        s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        s.setblocking(False)
        self.sock = s
        self.send(mav.MAVLink_heartbeat_message(mav.MAV_TYPE_GENERIC, 12, 0, 0, 0, 3))
        self.send(mav.MAVLink_command_long_message(
            0, 0, mav.MAV_CMD_SET_MESSAGE_INTERVAL, 0,
            mav.MAVLINK_MSG_ID_HIL_STATE_QUATERNION, 5000, 0, 0, 0, 0, 0))
        return self

    def close(self) -> None:
        if self.sock is not None:
            self.sock.close()
            self.sock = None

    def __enter__(self) -> Px4Peer:
        return self.connect()

    def __exit__(self, *exc) -> None:
        self.close()

    def send(self, msg) -> None:
        self.send_raw(msg.pack(self._encoder))

    def send_raw(self, data: bytes) -> None:
        self.sock.setblocking(True)
        try:
            self.sock.sendall(data)
        finally:
            self.sock.setblocking(False)

    # --- reading ----------------------------------------------------------------------------
    def _fill(self, timeout: float) -> bool:
        """Read what arrives within timeout; False if nothing did."""
        r, _, _ = select.select([self.sock], [], [], max(0.0, timeout))
        if not r:
            return False
        try:
            data = self.sock.recv(65536)
        except BlockingIOError:
            return False
        if not data:
            self.closed_by_bridge = True
            raise ConnectionError("the bridge closed the connection")
        self._pending.extend(self._parser.parse_buffer(data) or [])
        return True

    def recv_frame(self, limit_s: float = READ_LIMIT_S) -> Frame:
        """The next HIL_SENSOR and the messages that follow it in the same frame."""
        deadline = time.monotonic() + limit_s
        while not any(m.get_type() == "HIL_SENSOR" for m in self._pending):
            if not self._fill(deadline - time.monotonic()) and time.monotonic() > deadline:
                raise AssertionError(f"no HIL_SENSOR from the bridge within {limit_s} s")
        while self._pending[0].get_type() != "HIL_SENSOR":
            self._pending.pop(0)  # stray messages before the frame (none expected)
        frame = Frame(self._pending.pop(0))
        # the rest of the frame was sent with it; wait for the ground truth if expected
        while True:
            while self._pending and self._pending[0].get_type() != "HIL_SENSOR":
                m = self._pending.pop(0)
                if m.get_type() == "HIL_GPS":
                    frame.gps = m
                elif m.get_type() == "HIL_STATE_QUATERNION":
                    frame.state = m
                else:
                    frame.others.append(m)
            if not self.expect_ground_truth or frame.state is not None:
                break
            if not self._fill(deadline - time.monotonic()) and time.monotonic() > deadline:
                raise AssertionError("a frame without its HIL_STATE_QUATERNION")
        if self._pending == [] and not self.expect_ground_truth:
            self._fill(0.0)  # a HIL_GPS split off by the kernel arrives with it
            while self._pending and self._pending[0].get_type() == "HIL_GPS":
                frame.gps = self._pending.pop(0)
        self.last_time_usec = frame.time_usec
        self.frames_received += 1
        return frame

    def quiet(self, seconds: float) -> list:
        """Everything that arrives within `seconds` (the peer sends nothing meanwhile)."""
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self._fill(end - time.monotonic())
        out, self._pending = self._pending, []
        return out

    # --- answering, as PX4 does it ----------------------------------------------------------
    def answer(self, motors=(), *, armed: bool = True, lockstep: bool = True,
               time_usec: int | None = None) -> None:
        """HIL_ACTUATOR_CONTROLS for the last frame: motors 1..n in PX4's order."""
        controls = [0.0] * 16
        if armed:
            for i, u in enumerate(motors):
                controls[i] = float(u)
        mode = mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | (
            mav.MAV_MODE_FLAG_SAFETY_ARMED if armed else 0)
        self.send(mav.MAVLink_hil_actuator_controls_message(
            self.last_time_usec if time_usec is None else time_usec, controls, mode,
            mav.HIL_ACTUATOR_CONTROLS_FLAGS_LOCKSTEP if lockstep else 0))

    def step(self, motors=(), **kw) -> Frame:
        """Answer the last frame and receive the next."""
        self.answer(motors, **kw)
        return self.recv_frame()

    def fly(self, motors, n: int, **kw) -> list[Frame]:
        """n lockstep frames with constant motor outputs."""
        return [self.step(motors, **kw) for _ in range(n)]
