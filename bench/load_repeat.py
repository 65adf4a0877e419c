"""Run a selection of the test suite again and again while other processes keep every core
busy (issue 45's acceptance: the MAVLink trial tests and the MAVSDK example tests pass 30 of
30 consecutive runs with both cores loaded the whole time).

    FT_SITL_NAVRL_CHECKPOINT=/path/to/navrl_checkpoint.pt \\
        .venv/bin/python bench/load_repeat.py --runs 30 --log docs/results/load-repeat/run.log

Starts ``--burners`` CPU burners (default one per core: each a process spinning in a loop at
this script's own priority, as another job of the machine would) before the first run and
stops them after the last (or, with ``--load-cmd``, runs that command as the load instead: a
campaign is useful work that keeps the cores as busy), then runs ``pytest -p
no:cacheprovider -n 0 -q`` on the selection ``--runs`` times in a row. Each run's line in
the log: its number, start (UTC), duration, passed/failed/error/skipped counts from pytest's
summary, the load averages at its start and end, how many cores the load kept busy on
average while the run went on (its process groups' CPU seconds over the run's duration, from
/proc), the share of the machine's CPU time left idle, pytest's exit status; a failed run's
last lines of output follow it. The log ends with the summary line "N of K runs passed"; the
exit status is 1 when any run failed. Nothing is timed or asserted on speed: the durations
are for the record.

The runs use a snapshot of a commit (``--commit``, default HEAD; ``git archive`` into a
temporary directory, put first on every process's PYTHONPATH, the tests run from there), so
edits to the working tree while the runs go on (other people's, a checkout) reach none of
them: a change under a running test would fail it for a reason that is not a flake
(a Dask worker's code digest would differ from the campaign's). ``--live`` runs the
working tree as it is instead.
"""

from __future__ import annotations

import argparse
import datetime
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
#: the tests the acceptance names: the MAVLink trial tests and the MAVSDK example tests
DEFAULT_TESTS = ("tests/wire/test_wire_trials.py", "tests/wire/test_movers_wire.py",
                 "tests/mavlink/test_examples.py")
#: the lines of a failed run's output kept in the log
FAILED_TAIL = 60
#: a burner: a process that spins until it is killed
BURN = "while True:\n    pass\n"


def utc_now() -> str:
    return datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%dT%H:%M:%SZ")


def counts(output: str) -> dict[str, int]:
    """pytest's summary counts (``3 passed, 1 failed in 12.3s``) from a ``-q`` run's output."""
    found = {"passed": 0, "failed": 0, "error": 0, "skipped": 0}
    for line in reversed(output.splitlines()):
        pairs = re.findall(r"(\d+) (passed|failed|errors?|skipped|xfailed|xpassed)", line)
        if pairs and re.search(r" in [\d.]+s", line):
            for n, word in pairs:
                key = "error" if word.startswith("error") else word
                found[key] = found.get(key, 0) + int(n)
            break
    return found


def start_burners(n: int) -> list[subprocess.Popen]:
    """``n`` spinning processes at this process's priority (they inherit its niceness)."""
    return [subprocess.Popen([sys.executable, "-c", BURN], stdin=subprocess.DEVNULL,
                             stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            for _ in range(n)]


def start_load_command(cmd: str) -> subprocess.Popen:
    """``cmd`` (a shell command) as the load, in its own process group at this priority."""
    return subprocess.Popen(["bash", "-c", cmd], stdin=subprocess.DEVNULL,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            start_new_session=True)


def group_cpu_s(pgids: set[int]) -> float:
    """CPU seconds (user + system, with reaped children's) of the live processes whose
    process group is one of ``pgids``, from /proc; 0 where /proc is not readable."""
    tick = os.sysconf("SC_CLK_TCK")
    total = 0
    for entry in os.scandir("/proc"):
        if not entry.name.isdigit():
            continue
        try:
            with open(f"/proc/{entry.name}/stat") as f:
                fields = f.read().rsplit(")", 1)[1].split()
        except OSError:
            continue
        # after the command's ")": state ppid pgrp ... utime(12) stime(13) cutime cstime
        if int(fields[2]) in pgids:
            total += sum(int(x) for x in fields[11:15])
    return total / tick


def cpu_idle_s() -> float:
    """The machine's idle CPU seconds so far, over all cores (/proc/stat's idle + iowait)."""
    with open("/proc/stat") as f:
        fields = f.readline().split()  # cpu user nice system idle iowait ...
    return (int(fields[4]) + int(fields[5])) / os.sysconf("SC_CLK_TCK")


def stop_burners(burners: list[subprocess.Popen]) -> None:
    for p in burners:
        if p.poll() is None:
            try:  # a load command's whole group; a burner is its own process
                os.killpg(p.pid, signal.SIGTERM) if os.getpgid(p.pid) == p.pid else p.kill()
            except ProcessLookupError:
                pass
    for p in burners:
        try:
            p.wait(timeout=60)
        except subprocess.TimeoutExpired:
            os.killpg(p.pid, signal.SIGKILL)
            p.wait()


def load() -> str:
    return "/".join(f"{x:.2f}" for x in os.getloadavg())


def snapshot(commit: str) -> Path:
    """The files of ``commit`` in a new temporary directory (``git archive``)."""
    root = Path(tempfile.mkdtemp(prefix="ft-sitl-load-repeat-"))
    archive = subprocess.run(["git", "archive", commit], cwd=REPO, capture_output=True,
                             check=True).stdout
    subprocess.run(["tar", "-x", "-C", str(root)], input=archive, check=True)
    return root


def one_run(k: int, runs: int, tests: list[str], extra: list[str],
            burners: list[subprocess.Popen], log, tree: Path, env: dict) -> bool:
    """Run pytest once; its line (and a failure's tail) in the log. True when it passed."""
    alive = sum(p.poll() is None for p in burners)
    pgids = {os.getpgid(p.pid) for p in burners if p.poll() is None}
    cpu0, idle0 = group_cpu_s(pgids), cpu_idle_s()
    started, load0, t0 = utc_now(), load(), time.monotonic()
    # its own process group: stopping this script stops the run's processes too
    proc = subprocess.Popen([sys.executable, "-m", "pytest", "-p", "no:cacheprovider", "-n",
                             "0", "-q", *extra, *tests], cwd=tree, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            start_new_session=True)
    try:
        out, _ = proc.communicate()
    except BaseException:
        os.killpg(proc.pid, signal.SIGTERM)
        proc.wait()
        raise
    duration = time.monotonic() - t0
    # how many cores the load kept busy on average while this run went on
    busy = (group_cpu_s(pgids) - cpu0) / duration if duration > 0 else 0.0
    # ... and the share of the machine's CPU time nobody used
    idle = (cpu_idle_s() - idle0) / (duration * (os.cpu_count() or 1)) if duration > 0 else 0.0
    c = counts(out)
    ok = proc.returncode == 0 and c["failed"] == 0 and c["error"] == 0 and c["passed"] > 0
    line = (f"run {k:2d}/{runs}  start {started}  {duration:7.1f} s  passed {c['passed']:3d}"
            f"  failed {c['failed']}  error {c['error']}  skipped {c['skipped']}"
            f"  load {load0} -> {load()}  load procs {alive}/{len(burners)}"
            f"  load-cores {busy:.2f}  idle {100 * idle:.0f}%"
            f"  exit {proc.returncode}  {'PASS' if ok else 'FAIL'}")
    print(line, flush=True)
    log.write(line + "\n")
    if not ok:
        for tail_line in out.splitlines()[-FAILED_TAIL:]:
            log.write(f"    | {tail_line}\n")
    log.flush()
    return ok


def runs_so_far(log_path: Path, key: str) -> int:
    """How many runs of the count whose header ends in ``key`` the log holds, all passed and
    numbered 1..K in order (``--resume``): the count is the last header with that key and
    the resumptions after it. Raises ValueError naming what breaks it."""
    lines = log_path.read_text().splitlines() if log_path.exists() else []
    heads = [i for i, ln in enumerate(lines) if ln.startswith("# load_repeat ")]
    start = next((i for i in reversed(heads) if "(resumed at run" not in lines[i]), None)
    if start is None or lines[start].split(": ", 1)[1] != key:
        raise ValueError(f"{log_path}'s last count is not this one (the same runs, tests, load "
                         "and snapshot: pass --commit with the commit it names)")
    k = 0
    for ln in lines[start + 1:]:
        if ln.startswith("# load_repeat ") and ln.split(": ", 1)[1] != key:
            raise ValueError(f"{log_path}: another count began after this one's header")
        m = re.match(r"run +(\d+)/\d+ .* (PASS|FAIL)$", ln)
        if m:
            if int(m.group(1)) != k + 1 or m.group(2) != "PASS":
                raise ValueError(f"{log_path}: run {m.group(1)} of the count "
                                 f"{'failed' if m.group(2) == 'FAIL' else 'is out of order'}"
                                 ": the count cannot go on; start a new one")
            k += 1
    return k


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", type=int, default=30, help="consecutive runs (default 30)")
    ap.add_argument("--burners", type=int, default=os.cpu_count() or 1,
                    help="CPU burners kept running for the whole run (default: one per "
                         "core, here %(default)s)")
    ap.add_argument("--load-cmd", metavar="CMD",
                    help="a shell command to keep the cores busy instead of the burners (e.g. "
                         "a campaign: useful work as the load); started before the first "
                         "run at this script's priority, its process group stopped after "
                         "the last. Each run's line says how many cores it kept busy")
    ap.add_argument("--tests", nargs="+", default=list(DEFAULT_TESTS), metavar="PATH",
                    help="the test selection, as pytest takes it (default: "
                         + " ".join(DEFAULT_TESTS) + ")")
    ap.add_argument("--pytest-arg", action="append", default=[], metavar="ARG",
                    help="a further pytest argument (repeatable), e.g. --pytest-arg=-x")
    ap.add_argument("--commit", default="HEAD",
                    help="the commit whose snapshot the runs use (default HEAD)")
    ap.add_argument("--live", action="store_true",
                    help="run the working tree as it is, not a snapshot of --commit")
    ap.add_argument("--resume", action="store_true",
                    help="go on with the log's last count (same runs, tests, load and "
                         "--commit) from the run after its last one, when every run so far "
                         "passed: an interrupted count is resumed, never restarted quietly")
    ap.add_argument("--log", type=Path, default=REPO / "docs" / "results" / "load-repeat"
                    / "load_repeat.log", help="the log file (appended to; default %(default)s)")
    args = ap.parse_args(argv)
    if args.runs < 1:
        ap.error(f"--runs: {args.runs} must be at least 1")
    if args.burners < 0:
        ap.error(f"--burners: {args.burners} must be 0 or more")
    args.log.parent.mkdir(parents=True, exist_ok=True)

    def stop(signum, _frame):  # a kill or a closed terminal: stop burners and run cleanly
        raise SystemExit(f"stopped by signal {signum}")

    signal.signal(signal.SIGTERM, stop)
    signal.signal(signal.SIGHUP, stop)
    rev = subprocess.run(["git", "rev-parse", "--short", "HEAD" if args.live else args.commit],
                         cwd=REPO, capture_output=True, text=True)
    if rev.returncode != 0:
        ap.error(f"--commit: {args.commit!r} is not a commit of {REPO}")
    commit = rev.stdout.strip()
    env = dict(os.environ)
    if args.live:
        tree = REPO
        dirty = subprocess.run(["git", "status", "--porcelain"], cwd=REPO,
                               capture_output=True, text=True).stdout.strip()
        source = f"the working tree at {commit}{' with uncommitted changes' if dirty else ''}"
    else:
        tree = snapshot(commit)
        env["PYTHONPATH"] = os.pathsep.join([str(tree)] + (
            [env["PYTHONPATH"]] if env.get("PYTHONPATH") else []))
        source = f"a snapshot of commit {commit}"
    what = (f"the load command {args.load_cmd!r}" if args.load_cmd
            else f"{args.burners} CPU burners")
    key = (f"{args.runs} runs of pytest -p no:cacheprovider -n 0 -q "
           f"{' '.join(args.pytest_arg + args.tests)}; {what} on {os.cpu_count()} cores "
           f"(nice {os.nice(0)}); {source}; host {os.uname().nodename}")
    first = 1
    if args.resume:
        try:
            first = runs_so_far(args.log, key) + 1
        except ValueError as e:
            if tree != REPO:
                shutil.rmtree(tree, ignore_errors=True)
            ap.error(f"--resume: {e}")
    passed, done = first - 1, first - 1
    with open(args.log, "a") as log:
        resumed = f" (resumed at run {first})" if args.resume else ""
        head = f"# load_repeat {utc_now()}{resumed}: {key}"
        print(head, flush=True)
        log.write(head + "\n")
        burners = ([start_load_command(args.load_cmd)] if args.load_cmd
                   else start_burners(args.burners))
        t0 = time.monotonic()
        try:
            for k in range(first, args.runs + 1):
                passed += one_run(k, args.runs, args.tests, args.pytest_arg, burners, log,
                                  tree, env)
                done = k
        finally:
            alive = sum(p.poll() is None for p in burners)
            stop_burners(burners)
            early = "" if done == args.runs else f"; stopped after {done} runs"
            summary = (f"{passed} of {args.runs} runs passed ({time.monotonic() - t0:.0f} s"
                       f"{' for this part' if args.resume else ''}; "
                       f"load processes alive at the end: {alive}/{len(burners)}{early})")
            print(summary, flush=True)
            log.write(summary + "\n")
            if tree != REPO:
                shutil.rmtree(tree, ignore_errors=True)
    return 0 if passed == args.runs else 1


if __name__ == "__main__":
    sys.exit(main())
