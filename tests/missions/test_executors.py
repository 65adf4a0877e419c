"""Where trials fly (ft_sitl.missions.executors): the local pebble pool and a Dask cluster.

Local pool: a navigator stuck in compiled code (no signal handler can run) is ended by
killing its worker at its wall budget and recorded as a navigator error; the campaign
goes on. Dask: a real scheduler and two workers, each its own ``dask`` process on
loopback; a 40-trial campaign completes with rows equal to an in-process run's, also when
a worker is killed with SIGKILL mid-run and when the client is killed and restarted;
workers that run other code are refused by name.
"""

import collections
import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import psutil
import pytest

from ft_sitl.cli import main as cli_main
from ft_sitl.missions.campaign import run_campaign
from ft_sitl.missions.campaign_file import load_campaign
from ft_sitl.missions.executors import DIED_DETAIL, KILL_GRACE_S, DaskExecutor, ExecutorError
from ft_sitl.missions.results import COLUMNS
from ft_sitl.provenance import code_digest
from tests.missions.conftest import EXE, campaign_file, read_jsonl, run_exe, write_yard
from tests.missions.test_campaign import WALL_CLOCK, same

pytestmark = pytest.mark.e2e  # (tests/lanes.py)

DASK = Path(sys.executable).parent / "dask"

SPIN = """\
name = "spin"
trials = 2
platforms = ["1.00kg-SunnySky"]
scenarios = [{file = "yard.yaml"}]
algorithms = ["straight", "t_spin"]
[limits]
timeout_s = 2.0
"""


def test_a_navigator_hung_in_compiled_code_is_killed_at_its_budget(tmp_path, cli_env):
    write_yard(tmp_path)
    campaign = campaign_file(tmp_path, "spin.toml", SPIN)
    budget = 20.0
    env = {**cli_env, "FT_SITL_TRIAL_WALL_BUDGET_S": str(budget)}
    proc = run_exe("campaign", "run", campaign, "--out", tmp_path / "out", "--workers", "2",
                   "--no-report", "--quiet", env=env, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.startswith("4 trials run, 0 already done, 4 in the campaign;")
    rows = read_jsonl(tmp_path / "out" / "trials.jsonl")
    by = collections.defaultdict(list)
    for r in rows:
        by[r["algorithm"]].append(r)
    assert sorted(by) == ["straight", "t_spin"] and len(rows) == 4
    for r in by["t_spin"]:
        assert (r["reason"], r["success"]) == ("navigator_error", False)
        assert r["detail"] == (f"the trial overran its wall-clock budget of {budget:g} s "
                               "without returning to the simulator (hung in compiled "
                               "code?); its worker process was killed")
    assert [r["reason"] for r in by["straight"]] == ["timeout", "timeout"]
    runs = json.loads((tmp_path / "out" / "runs.json").read_text())
    assert runs[-1]["executor"] == "local" and runs[-1]["workers"] == 2
    # the trials that came back count in their worker's throughput; the killed ones do not
    assert sum(w["trials"] for w in runs[-1]["throughput"].values()) == 4
    assert set(runs[-1]["throughput"]) - {"killed"} and "killed" in runs[-1]["throughput"]
    assert KILL_GRACE_S < budget


# --- a Dask cluster of separate processes ---------------------------------------------------------
FORTY = """\
name = "forty"
trials = 10
seed = 5
platforms = ["1.00kg-SunnySky"]
scenarios = [{file = "yard_a.yaml"}, {file = "yard_b.yaml"}]
algorithms = ["straight", {name = "t_hover", label = "hover", params = {sleep_s = 0.4}}]
[limits]
timeout_s = 2.0
"""
N_FORTY = 2 * 10 * 2


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Cluster:
    """``dask scheduler`` and ``dask worker`` processes on loopback."""

    def __init__(self, env: dict, log_dir: Path):
        self.env = dict(env)  # default workers: daemonic processes, as dask-jobqueue's
        self.log_dir = log_dir
        self.port = _free_port()
        self.address = f"tcp://127.0.0.1:{self.port}"
        self.procs: list[subprocess.Popen] = []

    def _spawn(self, name: str, *args) -> subprocess.Popen:
        log = open(self.log_dir / f"{name}-{len(self.procs)}.log", "w")  # noqa: SIM115
        p = subprocess.Popen([str(DASK), *args], env=self.env, stdout=log, stderr=log,
                             start_new_session=True)
        self.procs.append(p)
        return p

    def start(self, workers: int = 2) -> "Cluster":
        self._spawn("scheduler", "scheduler", "--host", "127.0.0.1", "--port",
                    str(self.port), "--dashboard-address", "127.0.0.1:0")
        for _ in range(workers):
            # (--death-timeout: a worker whose test was killed does not linger)
            self._spawn("worker", "worker", self.address, "--nthreads", "1",
                        "--nworkers", "1", "--host", "127.0.0.1",
                        "--dashboard-address", "127.0.0.1:0", "--death-timeout", "60")
        from distributed import Client
        with Client(self.address, timeout=60) as c:
            c.wait_for_workers(workers, timeout=120)
        return self

    def worker_processes(self) -> list[psutil.Process]:
        """The worker processes proper (the nannies' children that run tasks)."""
        from distributed import Client
        with Client(self.address, timeout=60) as c:
            pids = c.run(os.getpid)
        return [psutil.Process(pid) for _, pid in sorted(pids.items())]

    def stop(self) -> None:
        for p in self.procs:
            try:
                os.killpg(p.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            p.wait()


@pytest.fixture(scope="module")
def forty(tmp_path_factory, cli_env):
    """The 40-trial campaign's directory and its in-process reference rows."""
    root = tmp_path_factory.mktemp("forty")
    for k, name in enumerate(("yard_a", "yard_b")):
        write_yard(root, name, wall=((2.0 + k, 9.8, 0.0), (8.0 - k, 10.2, 3.0)))
    campaign = campaign_file(root, "forty.toml", FORTY)
    old = sys.path[:]
    sys.path.insert(0, cli_env["PYTHONPATH"].split(os.pathsep)[0])
    try:
        summary = run_campaign(load_campaign(campaign), root / "reference", progress=False)
    finally:
        sys.path[:] = old
    assert (summary.ran, summary.errors) == (N_FORTY, [])
    ref = {r["trial_id"]: r for r in read_jsonl(root / "reference" / "trials.jsonl")}
    return root, campaign, ref


@pytest.fixture
def cluster(cli_env, tmp_path):
    c = Cluster(cli_env, tmp_path).start()
    yield c
    c.stop()


def _assert_equal_to_reference(out: Path, ref: dict) -> list[dict]:
    rows = read_jsonl(out / "trials.jsonl")
    ids = [r["trial_id"] for r in rows]
    assert len(ids) == len(set(ids)) == N_FORTY  # nothing lost, nothing twice
    assert set(ids) == set(ref)
    for r in rows:
        want = ref[r["trial_id"]]
        assert [k for k in COLUMNS if k not in WALL_CLOCK and not same(r[k], want[k])] == []
        # what made the row: this code, these libraries (the workers' = the client's)
        sw = json.loads(r["software"])
        assert sw["code"] == code_digest()[:16] and sw["numpy"] == np.__version__
    return rows


def _wait_for_rows(path: Path, n: int, proc: subprocess.Popen, timeout: float = 180):
    deadline = time.monotonic() + timeout
    while not (path.exists() and path.read_bytes().count(b"\n") >= n):
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < deadline, f"fewer than {n} trials finished in {timeout} s"
        time.sleep(0.05)


def test_a_worker_killed_mid_run_loses_and_duplicates_nothing(forty, cluster, cli_env,
                                                               tmp_path):
    root, campaign, ref = forty
    out = tmp_path / "out"
    proc = subprocess.Popen([EXE, "campaign", "run", str(campaign), "--out", str(out),
                             "--scheduler", cluster.address, "--chunk-size", "4",
                             "--no-report"], env=cli_env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        _wait_for_rows(out / "trials.jsonl", 6, proc)
        victims = cluster.worker_processes()
        assert len(victims) == 2, victims
        assert len(read_jsonl(out / "trials.jsonl")) < N_FORTY - 8  # mid-run
        for p in victims[0].children(recursive=True) + [victims[0]]:
            p.send_signal(signal.SIGKILL)  # the worker and the process its trials fly in
        stdout, stderr = proc.communicate(timeout=300)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, stderr
    assert stdout.startswith(f"{N_FORTY} trials run, 0 already done, {N_FORTY} in the "
                             "campaign;")
    assert "Dask dashboard: http://127.0.0.1:" in stderr  # the progress output names it
    assert "forty: 100%" in stderr  # the progress bar, with its rate and ETA
    assert read_jsonl(out / "trials.jsonl")[0]["trial_id"] in ref
    assert _assert_equal_to_reference(out, ref)
    run = json.loads((out / "runs.json").read_text())[-1]
    assert (run["executor"], run["scheduler"]) == ("dask", cluster.address)
    assert sum(w["trials"] for w in run["throughput"].values()) == N_FORTY
    assert all(w.startswith("tcp://127.0.0.1:") for w in run["throughput"])


def test_a_client_killed_and_restarted_completes_the_campaign_once(forty, cluster, cli_env,
                                                                    tmp_path):
    root, campaign, ref = forty
    out = tmp_path / "out"
    args = [EXE, "campaign", "run", str(campaign), "--out", str(out), "--scheduler",
            cluster.address, "--chunk-size", "4", "--no-report", "--quiet"]
    proc = subprocess.Popen(args, env=cli_env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, start_new_session=True)
    try:
        _wait_for_rows(out / "trials.jsonl", 6, proc)
    finally:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.communicate()
    before = len(read_jsonl(out / "trials.jsonl"))
    assert 6 <= before < N_FORTY
    again = subprocess.run(args, env=cli_env, capture_output=True, text=True, timeout=300)
    assert again.returncode == 0, again.stderr
    assert again.stdout.startswith(f"{N_FORTY - before} trials run, {before} already done")
    _assert_equal_to_reference(out, ref)


def test_a_restarted_scheduler_and_workers_complete_the_campaign_once(forty, cluster,
                                                                        cli_env, tmp_path):
    root, campaign, ref = forty
    out = tmp_path / "out"
    proc = subprocess.Popen([EXE, "campaign", "run", str(campaign), "--out", str(out),
                             "--scheduler", cluster.address, "--chunk-size", "4",
                             "--no-report", "--quiet"], env=cli_env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        _wait_for_rows(out / "trials.jsonl", 6, proc)
        cluster.stop()  # the scheduler and its workers, with SIGKILL
        assert len(read_jsonl(out / "trials.jsonl")) < N_FORTY - 8  # mid-run
        time.sleep(2.0)
        cluster.procs = []
        cluster.start()  # a new scheduler on the same address, new workers
        stdout, stderr = proc.communicate(timeout=300)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, stderr
    assert stdout.startswith(f"{N_FORTY} trials run, 0 already done")
    _assert_equal_to_reference(out, ref)


def test_a_local_dask_cluster_flies_the_campaign(forty, cli_env, tmp_path):
    root, campaign, ref = forty
    env = {**cli_env}
    proc = run_exe("campaign", "run", campaign, "--out", tmp_path / "out", "--cluster",
                   "local", "--workers", "2", "--no-report", "--quiet", env=env,
                   timeout=300)
    assert proc.returncode == 0, proc.stderr
    _assert_equal_to_reference(tmp_path / "out", ref)
    run = json.loads((tmp_path / "out" / "runs.json").read_text())[-1]
    assert (run["executor"], run["scheduler"], run["workers"]) == ("dask", "local cluster", 2)


def test_default_daemonic_workers_fly_trials_in_a_child_that_dies_alone(tmp_path, cluster,
                                                                        cli_env):
    """Workers started the default way (daemonic, as dask-jobqueue and managed clusters
    start them) fly each trial in a child of their own started with subprocess: a
    navigator hung in compiled code is killed at its budget, one that kills its process
    fails alone (after one more try in a fresh child), and the others fly."""
    import multiprocessing as mp

    from distributed import Client

    with Client(cluster.address, timeout=60) as c:
        assert all(c.run(lambda: mp.current_process().daemon).values())
    write_yard(tmp_path)
    campaign = campaign_file(tmp_path, "bad.toml", SPIN.replace(
        'algorithms = ["straight", "t_spin"]', 'algorithms = ["straight", "t_spin", '
        '"t_killer"]'))
    # (within the budget a fresh child builds the scene and loads the compiled kernels, ~5 s
    # on an idle machine; in a fresh clone under the suite's load it may compile some of
    # them first: 30 s once failed the straight trials in CI, so 60 s as before 413d9e8)
    budget = 60.0
    env = {**cli_env, "FT_SITL_TRIAL_WALL_BUDGET_S": str(budget)}
    proc = run_exe("campaign", "run", campaign, "--out", tmp_path / "out", "--scheduler",
                   cluster.address, "--chunk-size", "1", "--no-report", "--quiet", env=env,
                   timeout=600)
    assert proc.returncode == 0, proc.stderr
    rows = read_jsonl(tmp_path / "out" / "trials.jsonl")
    by = collections.defaultdict(list)
    for r in rows:
        by[r["algorithm"]].append(r)
    assert {k: len(v) for k, v in by.items()} == {"straight": 2, "t_spin": 2, "t_killer": 2}
    assert [r["reason"] for r in by["straight"]] == ["timeout", "timeout"]
    assert {r["detail"] for r in by["t_spin"]} == {
        f"the trial overran its wall-clock budget of {budget:g} s without returning to the "
        "simulator (hung in compiled code?); its worker process was killed"}
    assert {r["detail"] for r in by["t_killer"]} == {DIED_DETAIL}
    assert all(r["reason"] == "navigator_error" for r in by["t_spin"] + by["t_killer"])
    with Client(cluster.address, timeout=60) as c:
        assert len(c.scheduler_info()["workers"]) == 2  # no worker was lost on the way


def test_workers_with_other_code_are_refused(cluster, monkeypatch):
    ex = DaskExecutor(scheduler=cluster.address)
    ex.start()
    try:
        import ft_sitl.missions.executors as executors
        real = executors.code_digest()
        monkeypatch.setattr(executors, "code_digest", lambda: "0" * 64)
        with pytest.raises(ExecutorError) as exc:
            ex.check_workers()
        lines = str(exc.value).splitlines()
        assert lines[0] == "workers refused:"
        assert len(lines) == 3 and all(
            f"with code digest {real[:12]}, this campaign " in line and
            "install the same ft-sitl there" in line for line in lines[1:])
    finally:
        ex.close()


def test_bad_scheduler_options_are_named(tmp_path, cli_env, forty, capsys):
    _, campaign, _ = forty
    cases = [  # refused before anything starts: the command's own function, in-process
        (["--scheduler", "localhost:8786"], "--scheduler: 'localhost:8786' is not a scheduler "
                                            "address like tcp://host:8786"),
        (["--scheduler", "tcp://127.0.0.1:9", "--cluster", "local"],
         "--scheduler and --cluster: give one"),
        (["--chunk-size", "3"], "--chunk-size: only with --scheduler or --cluster"),
        (["--cluster", "local", "--chunk-size", "0"], "--chunk-size: 0 must be at least 1"),
    ]
    plain = tmp_path / "plain.toml"  # (built-in navigators only: no test plug-ins here)
    plain.write_text('name = "plain"\nalgorithms = ["straight"]\nplatforms = ["real"]\n'
                     'scenarios = ["forest"]\nindices = [1]\ntrials = 1\n')
    for extra, message in cases:
        code = cli_main(["campaign", "run", str(plain), "--out", str(tmp_path / "o"),
                         "--quiet", *extra])
        err = capsys.readouterr().err
        assert code == 2 and message in err, (extra, err)
        assert not (tmp_path / "o").exists()
    # a scheduler nobody listens at: found out by the installed command, exit 2
    proc = run_exe("campaign", "run", campaign, "--out", tmp_path / "o", "--quiet",
                   "--scheduler", f"tcp://127.0.0.1:{_free_port()}", env=cli_env, timeout=120)
    assert proc.returncode == 2 and "--scheduler tcp://127.0.0.1:" in proc.stderr, proc.stderr
    assert "Traceback" not in proc.stderr
