"""A test's vehicles: an ``ft-sitl sitl`` process on free instance numbers, ready when its
simulation runs, stopped with its telemetry log closed.

Why a process and not a server thread in the test's interpreter: the simulator steps
1 kHz physics in Python; in the test's process it would share the interpreter lock with
the test's own clients (pymavlink parses every message in Python) and each would slow the
other unpredictably, which is how SITL tests turn flaky. A process of its own also keeps
the simulator's numeric settings (``import ft_sitl`` pins them) out of the user's tests,
survives a test that blocks its event loop, and is the ``ft-sitl sitl`` a user runs by hand,
so a failing test can be replayed outside pytest with the same command line
(:attr:`Sitl.command`).
"""

from __future__ import annotations

import json
import queue
import shlex
import signal
import socket
import subprocess
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path

#: the readiness probe's MAVLink ids: an onboard computer, not a ground station
PROBE_SYSID, PROBE_COMPID = 252, 191
#: wall seconds between the probe's heartbeats
PROBE_PERIOD_S = 0.2
#: wall seconds a stopping vehicle gets to close its log before it is killed
STOP_GRACE_S = 30.0
#: lines of the vehicle's log an error quotes
LOG_TAIL_LINES = 15


class SitlStartError(RuntimeError):
    """The vehicles did not start serving (a bad option, taken ports, a hang)."""


@dataclass(frozen=True)
class Ports:
    """One vehicle's UDP ports (PX4 SITL instance i's)."""

    client: int  #: 14540+i: the API link sends here; MAVSDK/pymavlink listen on it
    api_listen: int  #: 14580+i: the API link listens here
    gcs_listen: int  #: 18570+i: the GCS link listens here


@dataclass(frozen=True)
class Vehicle:
    """How a test's client reaches one served vehicle."""

    sysid: int  #: MAVLink system id (component 1)
    instance: int  #: PX4 SITL instance number
    mavsdk_url: str  #: for MAVSDK's add_any_connection / connect: udpin://0.0.0.0:14540+i
    pymavlink_url: str  #: for mavutil.mavlink_connection: udpin:0.0.0.0:14540+i
    gcs_url: str  #: a ground station's own link: udpout:127.0.0.1:18570+i
    ports: Ports
    mqtt_url: str | None = None  #: the MQTT bus (option mqtt=True), else None


def _vehicles(info: dict) -> list[Vehicle]:
    out = []
    for v in info["vehicles"]:
        host = v["api_listen"].rsplit(":", 1)[0]
        host = "127.0.0.1" if host in ("0.0.0.0", "") else host
        ports = Ports(**v["ports"])
        out.append(Vehicle(sysid=v["sysid"], instance=v["instance"], mavsdk_url=v["mavsdk"],
                           pymavlink_url=v["pymavlink"],
                           gcs_url=f"udpout:{host}:{ports.gcs_listen}", ports=ports,
                           mqtt_url=v.get("mqtt")))
    return out


class Sitl:
    """A running ``ft-sitl sitl`` process and its vehicles (made by :func:`serve`)."""

    def __init__(self, proc: subprocess.Popen, command: list[str], log_dir: Path,
                 info: dict, lines: queue.Queue, reader: threading.Thread):
        self.proc = proc
        self.command = command
        self.log_dir = log_dir
        self.info = info
        self.vehicles = _vehicles(info)
        self._reader = reader
        self._lines = lines
        #: wall seconds from the process's start to its first simulated step being served
        self.startup_s: float | None = None
        #: the exit status when the process ended by itself before stop() (a crash)
        self.exited_early: int | None = None
        self._stopped = False

    @property
    def tlog(self) -> Path:
        """The telemetry log: every MAVLink packet sent and received, all vehicles."""
        return self.log_dir / "flight.tlog"

    @property
    def log(self) -> Path:
        """The process's output (its stderr, and stdout after the vehicle list)."""
        return self.log_dir / "sitl.log"

    @property
    def running(self) -> bool:
        return self.proc.poll() is None

    def stop(self) -> int:
        """Stop the process (SIGTERM, the way Ctrl-C stops it: the log is closed), killing
        it after STOP_GRACE_S; returns its exit status. Idempotent."""
        if self.proc.poll() is not None:
            if not self._stopped:  # it ended by itself while in use
                self.exited_early = self.proc.returncode
        else:
            self.proc.send_signal(signal.SIGTERM)
            try:
                self.proc.wait(STOP_GRACE_S)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self._stopped = True
        self._reader.join(STOP_GRACE_S)
        if self.proc.stdout is not None:
            self.proc.stdout.close()
        return self.proc.returncode

    def __enter__(self) -> Sitl:
        return self

    def __exit__(self, *exc) -> None:
        self.stop()

    def replay_command(self) -> str:
        """The command line that serves the same vehicles by hand (a shell line), without
        the plugin's --json and --tlog (which would append to this flight's log)."""
        args, rest = [], iter(self.command[3:])
        for a in rest:
            if a == "--tlog":
                next(rest, None)
            elif a != "--json":
                args.append(a)
        return shlex.join(["ft-sitl", *args])


def log_tail(path: Path, n: int = LOG_TAIL_LINES) -> str:
    try:
        lines = path.read_text(errors="replace").splitlines()
    except OSError:
        return "(no log)"
    return "\n".join(lines[-n:]) or "(empty)"


def _read_stdout(stdout, lines: queue.Queue, log: Path) -> None:
    """Hand the lines of the vehicle list to the starter, append the rest to the log."""
    in_json = True
    for line in stdout:
        if in_json:
            lines.put(line)
            in_json = line.rstrip() != "}"
        else:
            with open(log, "a") as fh:
                fh.write(line)
    lines.put(None)


def _read_info(proc, lines: queue.Queue, deadline: float, log: Path, where: str) -> dict:
    text = ""
    while True:
        try:
            line = lines.get(timeout=max(0.0, deadline - time.monotonic()))
        except queue.Empty:
            raise SitlStartError(f"{where}: no vehicle list from ft-sitl sitl by the start "
                                 f"timeout; its log {log}:\n{log_tail(log)}") from None
        if line is None:
            proc.wait()
            raise SitlStartError(f"{where}: ft-sitl sitl exited with status "
                                 f"{proc.returncode} before serving:\n{log_tail(log)}")
        text += line
        if line.rstrip() == "}":
            return json.loads(text)


def _wait_serving(proc, host: str, port: int, deadline: float, log: Path,
                  where: str) -> None:
    """Until the vehicle on ``port`` (a GCS listen port) answers with telemetry stamped
    after its first simulated step: the simulation runs (its kernels compiled)."""
    from pymavlink.dialects.v20 import common as mav  # loaded only when a vehicle starts

    enc = mav.MAVLink(None, PROBE_SYSID, PROBE_COMPID)
    hb = enc.heartbeat_encode(mav.MAV_TYPE_ONBOARD_CONTROLLER, mav.MAV_AUTOPILOT_INVALID,
                              0, 0, 0).pack(enc)
    parser = mav.MAVLink(None, 0, 0)
    parser.robust_parsing = True
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind((host, 0))
        s.settimeout(PROBE_PERIOD_S)
        while True:
            if proc.poll() is not None:
                raise SitlStartError(f"{where}: ft-sitl sitl exited with status "
                                     f"{proc.returncode} while starting:\n{log_tail(log)}")
            if time.monotonic() > deadline:
                raise SitlStartError(f"{where}: the vehicle on UDP port {port} did not serve "
                                     f"by the start timeout (numba compiles the simulator "
                                     f"on the first start after an install: raise "
                                     f"--ft-sitl-start-timeout); its log {log}:\n"
                                     f"{log_tail(log)}")
            s.sendto(hb, (host, port))
            try:
                data = s.recv(65535)
            except TimeoutError:
                continue
            for m in parser.parse_buffer(data) or []:
                if getattr(m, "time_boot_ms", 0) > 0:
                    return


def serve(argv: list[str], log_dir: Path, timeout_s: float, where: str) -> Sitl:
    """Start ``ft-sitl sitl`` with ``argv`` (:func:`ft_sitl_pytest.options.sitl_arguments`)
    and the plugin's --json and --tlog, its files in ``log_dir``; returns once its vehicles
    are served, or raises :class:`SitlStartError` with the process's last lines."""
    log_dir.mkdir(parents=True, exist_ok=True)
    command = [sys.executable, "-m", "ft_sitl", "sitl", "--json",
               "--tlog", str(log_dir / "flight.tlog"), *argv]
    log = log_dir / "sitl.log"
    t0 = time.monotonic()
    deadline = t0 + timeout_s
    with open(log, "a") as err:
        proc = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=err, text=True,
                                stdin=subprocess.DEVNULL)
    lines: queue.Queue = queue.Queue()
    reader = threading.Thread(target=_read_stdout, args=(proc.stdout, lines, log),
                              daemon=True, name=f"ft-sitl {log_dir.name}")
    reader.start()
    try:
        info = _read_info(proc, lines, deadline, log, where)
        sitl = Sitl(proc, command, log_dir, info, lines, reader)
        first = sitl.vehicles[0]
        host = first.gcs_url.split(":")[1]
        _wait_serving(proc, host, first.ports.gcs_listen, deadline, log, where)
    except BaseException:
        if proc.poll() is None:
            proc.kill()
        proc.wait()
        reader.join(STOP_GRACE_S)
        raise
    sitl.startup_s = time.monotonic() - t0
    return sitl
