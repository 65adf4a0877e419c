"""What both wire transports (:mod:`~ft_sitl.transport.mavlink_trial`, free-running, and
:mod:`~ft_sitl.transport.lockstep`) set up and take down around one trial: the trial's
plan, vehicle and referee as in-process, a SITL instance number, the vehicle served by
the chosen autopilot's face (:mod:`~ft_sitl.transport.faces`), and the navigator
process with its stdout and stderr files."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import tempfile
import time
from pathlib import Path

from ft_sitl.mavlink.instances import InstanceLock
from ft_sitl.missions.plan import PERCEPTION_WIRE, plan_trial
from ft_sitl.missions.protocol import TrialFailure, TrialReferee, trial_vehicle
from ft_sitl.missions.results import Outcome
from ft_sitl.missions.spec import TrialSpec, TrialSpecError
from ft_sitl.transport.faces import DEFAULT_AUTOPILOT, check_autopilot, serve


class WireTrial:
    """One trial's set-up for a wire transport. Make it, then :meth:`serve` the vehicle
    and :meth:`start` the navigator inside ``try``, and :meth:`close` in ``finally``
    (the navigator stopped, the server closed, the instance given back)."""

    def __init__(self, spec: TrialSpec, *, record: bool = False, instance: int | None = None,
                 log_dir: Path | None = None, autopilot: str = DEFAULT_AUTOPILOT):
        if spec.perception is not None:
            raise TrialSpecError(PERCEPTION_WIRE)
        self.spec = spec
        self.autopilot = check_autopilot(autopilot)
        self.wall0 = time.perf_counter()
        self.plan = plan_trial(spec)
        self.guard, self.fleet = trial_vehicle(self.plan)
        self.ref = TrialReferee(self.fleet, self.guard, self.plan, record=record)
        #: the vehicle's name on the bus (its topics)
        self.vehicle = spec.trial_id
        logs = Path(log_dir or tempfile.mkdtemp(prefix="ft-sitl-nav-"))
        logs.mkdir(parents=True, exist_ok=True)
        self.out_path = logs / f"{spec.trial_id}.out"
        self.err_path = logs / f"{spec.trial_id}.err"
        self.server = None
        self.proc = None
        self._lock = InstanceLock() if instance is None else None
        self.instance = self._lock.__enter__() if self._lock is not None else instance

    def serve(self, *, lockstep: bool, speed_factor: float = 1.0,
              pace_span_s: float | None = None):
        """The vehicle served by the face (client-paced with ``pace_span_s``); (server, the
        client's connection URL)."""
        self.server, connect = serve(self.autopilot, self.fleet, self.instance,
                                     lockstep=lockstep, speed_factor=speed_factor,
                                     pace_span_s=pace_span_s)
        return self.server, connect

    def start(self, argv: list[str], env: dict) -> subprocess.Popen:
        """The navigator process (its own session; stdout and stderr to the log files);
        a navigator error if it cannot start."""
        with open(self.out_path, "wb") as out_fh, open(self.err_path, "wb") as err_fh:
            try:
                self.proc = subprocess.Popen(argv, stdout=out_fh, stderr=err_fh,
                                             env={**os.environ, **env},
                                             start_new_session=True)
            except OSError as exc:
                raise TrialFailure(Outcome.NAVIGATOR_ERROR,
                                   f"cannot start {argv[0]}: {exc}") from None
        return self.proc

    def client_summary(self) -> dict:
        """The navigator process's JSON summary line (empty if it wrote none)."""
        return client_result(self.out_path)

    def client_failed(self) -> str:
        """The navigator's stderr's last line (a failed trial's detail)."""
        return tail(self.err_path)

    def stop_client(self) -> None:
        """Stop the navigator process (SIGTERM: ``ft-sitl navigate`` prints its summary)."""
        if self.proc is not None:
            stop_client(self.proc)

    def close(self) -> None:
        """Stop the navigator, close the server, give the instance back (in that order:
        the instance's ports are free before another trial may take it)."""
        self.stop_client()
        if self.server is not None:
            self.server.close()
        if self._lock is not None:
            self._lock.__exit__(None, None, None)
            self._lock = None

def client_result(path: Path) -> dict:
    """The navigator process's JSON summary line (empty if it wrote none)."""
    try:
        lines = path.read_text(errors="replace").strip().splitlines()
        return json.loads(lines[-1]) if lines else {}
    except (OSError, json.JSONDecodeError):
        return {}


def tail(path: Path, n: int = 300) -> str:
    """The last line of a navigator process's stderr (for a failed trial's detail)."""
    try:
        lines = [ln for ln in path.read_text(errors="replace").splitlines() if ln.strip()]
    except OSError:
        return ""
    return lines[-1][-n:] if lines else "the navigator process failed (no output)"


def stop_client(proc) -> None:
    """SIGTERM to the navigator process's group (``ft-sitl navigate`` prints its summary),
    then SIGKILL after 5 s."""
    if proc.poll() is not None:
        return
    try:
        os.killpg(proc.pid, signal.SIGTERM)
    except (ProcessLookupError, PermissionError):
        pass
    try:
        proc.wait(5.0)
    except subprocess.TimeoutExpired:
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except (ProcessLookupError, PermissionError):
            pass
        proc.wait(5.0)
