"""The ArduCopter face for the tests, on free instance numbers only (their lock files held,
their TCP ports free), so tests never collide with each other or with a SITL or trial of
this machine: in this process (:func:`free_ardupilot_sitl`) or as ``ft-sitl sitl
--autopilot ardupilot --instance auto`` in a process of its own
(:func:`ardupilot_sitl_process`, for clients that run their own threads: DroneKit, MAVSDK);
MAVProxy, unmodified, typed at on such an instance (:func:`mavproxy_session`); a
pymavlink link to its SERIAL0 (:func:`serial0`).
Waits with deadlines that fail naming what was awaited (pymavlink's own
``motors_disarmed_wait`` waits for ever)."""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import time
from contextlib import contextmanager
from pathlib import Path

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

from ft_sitl.mavlink.ardupilot.server import (  # noqa: E402
    ArduPilotServer,
    serial_ports_free,
    tcp_ports,
)
from ft_sitl.mavlink.instances import free_instances  # noqa: E402

from .sitl_harness import _running_sitl  # noqa: E402

#: the seconds a started process may take to print where it serves (a cold numba cache)
START_TIMEOUT_S = 300.0
#: MAVProxy, unmodified, as installed beside ft-sitl (pyproject's test extra)
MAVPROXY = Path(sys.executable).parent / "mavproxy.py"


@contextmanager
def free_ardupilot_sitl(**kwargs):
    """An ArduCopter face in this process on a free instance number (held meanwhile);
    yields ``(server, k)``: SERIAL0 is ``tcp:127.0.0.1:{tcp_ports(k)[0]}``."""
    with free_instances(1, serial_ports_free) as k, \
            _running_sitl(1, server_class=ArduPilotServer, base_instance=k, **kwargs) as s:
        yield s, k


@contextmanager
def serial0(k: int, timeout_s: float = 30.0):
    """A pymavlink link (as ground station 250) to instance ``k``'s SERIAL0, its first
    HEARTBEAT received (``conn.messages["HEARTBEAT"]``), closed at the end."""
    conn = mavutil.mavlink_connection(f"tcp:127.0.0.1:{tcp_ports(k)[0]}", source_system=250)
    try:
        conn.wait_heartbeat(timeout=timeout_s)
        yield conn
    finally:
        conn.close()


@contextmanager
def ardupilot_sitl_process(*args: str):
    """``ft-sitl sitl --autopilot ardupilot --instance auto --json --no-mqtt *args`` in a
    process of its own; yields the vehicles' description it prints (``vehicles[0]
    ["serial"][0]`` is SERIAL0's tcp:HOST:PORT). The process is stopped at the end."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "ft_sitl", "sitl", "--autopilot", "ardupilot", "--instance",
         "auto", "--json", "--no-mqtt", *args],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        text, line, deadline = "", "", time.monotonic() + START_TIMEOUT_S
        while line.rstrip("\n") != "}":  # (the closing brace of the top level)
            line = proc.stdout.readline()
            if not line or time.monotonic() > deadline:
                proc.kill()
                raise AssertionError(f"ft-sitl sitl did not start: {proc.stderr.read()}")
            text += line
        info = json.loads(text)
        host, port = info["vehicles"][0]["serial"][0].split(":")[1:]
        until(lambda: _accepts(host, int(port)), START_TIMEOUT_S,
              f"ft-sitl sitl to listen on {host}:{port}")
        yield info
    finally:
        if proc.poll() is None:
            proc.terminate()
            try:
                proc.wait(30)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        proc.stdout.close()
        proc.stderr.close()


class MavproxySession:
    """A running MAVProxy: commands typed on its stdin, what it printed in ``log``."""

    def __init__(self, proc: subprocess.Popen, log: Path):
        self.proc, self.log = proc, log

    def type(self, line: str) -> None:
        """``line`` typed at MAVProxy's prompt."""
        self.proc.stdin.write(line + "\n")
        self.proc.stdin.flush()

    def output(self) -> str:
        """All MAVProxy has printed so far."""
        return self.log.read_text() if self.log.exists() else ""

    def until(self, what, timeout_s: float, describe: str) -> None:
        """:func:`until`, failing with the tail of what MAVProxy printed."""
        try:
            until(what, timeout_s, describe)
        except AssertionError as exc:
            raise AssertionError(f"{exc}; MAVProxy said:\n{self.output()[-1500:]}") from None

    def take_off(self, agent, metres: float = 10.0) -> None:
        """``mode guided``, ``arm throttle``, ``takeoff METRES`` typed as a user does, each
        awaited on the vehicle (``agent``: the face's agent), up to half a metre short."""
        c = agent.cmd
        ground = c.home[2]
        self.type("mode guided")
        self.until(lambda: agent.mode_name == "GUIDED", 30, "GUIDED")
        self.type("arm throttle")
        self.until(lambda: c.armed, 30, "armed")
        self.type(f"takeoff {metres:g}")
        self.until(lambda: c.position_now()[2] - ground > metres - 0.5, 60, f"{metres:g} m up")


@contextmanager
def mavproxy_session(k: int, workdir: Path):
    """MAVProxy on instance k's SERIAL0 (``--master=tcp:127.0.0.1:PORT``; its state, tlog
    and printed output, ``mavproxy.out``, in ``workdir``), yielded once it has fetched the
    vehicle's parameters (it reads commands once it has the vehicle's heartbeat); killed at
    the end."""
    log = workdir / "mavproxy.out"
    with open(log, "w") as out:
        proc = subprocess.Popen(
            [sys.executable, str(MAVPROXY), f"--master=tcp:127.0.0.1:{tcp_ports(k)[0]}",
             f"--state-basedir={workdir}", "--logfile", str(workdir / "mav.tlog")],
            stdin=subprocess.PIPE, stdout=out, stderr=subprocess.STDOUT, text=True,
            cwd=workdir)
    session = MavproxySession(proc, log)
    try:
        session.until(lambda: "Received" in session.output(), 60,
                      "MAVProxy's parameter fetch")
        yield session
    finally:
        proc.kill()
        proc.wait(10)
        proc.stdin.close()


def _accepts(host: str, port: int) -> bool:
    """Whether a TCP connection to host:port is accepted now (then closed)."""
    try:
        socket.create_connection((host, port), timeout=1.0).close()
    except OSError:
        return False
    return True


def wait_for(conn, what=lambda m: True, timeout_s: float = 60.0, describe: str = "",
             **match):
    """The first message matching ``match`` (pymavlink's recv_match keywords: ``type``,
    a condition) for which ``what`` holds, within ``timeout_s`` wall seconds
    (AssertionError naming what was awaited)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        m = conn.recv_match(blocking=True, timeout=1.0, **match)
        if m is not None and what(m):
            return m
    raise AssertionError(f"no {match or 'message'} {describe or 'matching'} within "
                         f"{timeout_s:g} s")


def wait_msg(conn, types, what=lambda m: True, timeout_s: float = 60.0, describe: str = ""):
    """:func:`wait_for` of messages of ``types``."""
    return wait_for(conn, what, timeout_s, describe, type=types)


def command_ack(conn, command: int, timeout_s: float = 10.0):
    """The COMMAND_ACK of ``command``."""
    return wait_for(conn, lambda m: m.command == command, timeout_s, f"for command {command}",
                    type="COMMAND_ACK")


def upload_mission(conn, loader) -> int:
    """The mission protocol's upload as a ground station drives it: MISSION_COUNT, each
    item the vehicle asks for from ``loader`` (pymavlink's MAVWPLoader), the vehicle's
    MISSION_ACK (its result)."""
    conn.waypoint_count_send(loader.count())
    while True:
        m = wait_for(conn, lambda m: True, 10.0,
                     type=["MISSION_REQUEST", "MISSION_REQUEST_INT", "MISSION_ACK"])
        if m.get_type() == "MISSION_ACK":
            return m.type
        w = loader.wp(m.seq)
        w.target_system, w.target_component = conn.target_system, conn.target_component
        conn.mav.send(w)

def wait_disarmed(conn, timeout_s: float = 180.0):
    """pymavlink's motors_disarmed_wait with a deadline: the vehicle's HEARTBEAT without
    the armed flag."""
    armed = mavutil.mavlink.MAV_MODE_FLAG_SAFETY_ARMED
    return wait_msg(conn, "HEARTBEAT",
                    lambda m: m.get_srcSystem() == conn.target_system and
                    not m.base_mode & armed, timeout_s, "saying disarmed")


def wait_armed(conn, timeout_s: float = 30.0):
    """pymavlink's motors_armed_wait with a deadline."""
    armed = mavutil.mavlink.MAV_MODE_FLAG_SAFETY_ARMED
    return wait_msg(conn, "HEARTBEAT",
                    lambda m: m.get_srcSystem() == conn.target_system and
                    bool(m.base_mode & armed), timeout_s, "saying armed")


def until(what, timeout_s: float, describe: str, poll_s: float = 0.1):
    """Poll ``what()`` until it is true, within ``timeout_s`` wall seconds (a liveness
    deadline, not a timing assertion: AssertionError naming what was awaited)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if what():
            return
        time.sleep(poll_s)
    raise AssertionError(f"timed out after {timeout_s:g} s waiting for {describe}")
