"""Run MAVSDK-Python's official examples, unmodified, against `ft-sitl sitl`.

The examples are not part of this repository: fetch them first, e.g.

    git clone --depth 1 https://github.com/mavlink/MAVSDK-Python /tmp/MAVSDK-Python
    .venv/bin/python scripts/run_mavsdk_examples.py /tmp/MAVSDK-Python/examples

Each example gets a fresh vehicle (`python -m ft_sitl sitl --no-mqtt --tlog ...`, on PX4
SITL's default ports, which the examples hard-code; the telemetry log is the one log the
vehicle has to list and download), its own copy of the examples directory as working
directory (they write downloads there), a stdin that stays open and empty (a terminal
nobody types into: with `/dev/null`, `shell.py` fails where it does not in a terminal)
and a timeout. The examples use the old gRPC API (`from mavsdk import System`); this
script runs each through itself (`--as-mavsdk`), which aliases `mavsdk` and its
submodules to the installed `mavsdk_grpc` package (the same code under its new name)
before running the example as `__main__`. Examples that talk to an already running
`mavsdk_server` (`System(mavsdk_server_address="localhost", port=50051)`, as the FTP ones
do) get one, as their documentation asks: the bundled `mavsdk_server -p 50051
udpin://0.0.0.0:14540`; the serial address they pass to `connect()` is then not used.

Outcome per example: `completes` (exit 0), `fails` (non-zero exit, or a traceback after
which the script stays silent: mavsdk_grpc's System keeps a thread alive, so a script
whose coroutine raised never exits by itself; the exception line says why) or `timeout`
(still running after `--timeout` s: a hang, or an example that runs until stopped by
design). Results go to stdout as a table, and with `--json` to a file. Not part of the
test suite: it needs the fetched examples and takes about an hour.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import json
import os
import pkgutil
import re
import runpy
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: the ports the examples and PX4 SITL instance 0 use (MAVSDK, vehicle API, vehicle GCS,
#: mavsdk_server's gRPC)
UDP_PORTS = (14540, 14580, 18570)
GRPC_PORT = 50051
READY_LINE = "Ctrl-C stops."


def as_mavsdk(example: str, args: list[str]) -> None:
    """Run ``example`` as ``__main__`` with ``mavsdk`` meaning ``mavsdk_grpc``."""
    import mavsdk_grpc  # (only in this mode: the runner itself does not need it)

    sys.modules["mavsdk"] = mavsdk_grpc
    for info in pkgutil.iter_modules(mavsdk_grpc.__path__):
        sys.modules[f"mavsdk.{info.name}"] = importlib.import_module(
            f"mavsdk_grpc.{info.name}")
    sys.argv = [example, *args]
    sys.path.insert(0, str(Path(example).parent))
    runpy.run_path(example, run_name="__main__")


def ports_free() -> list[int]:
    """The ports this run needs that something else holds."""
    busy = []
    for port in UDP_PORTS:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            try:
                s.bind(("0.0.0.0", port))
            except OSError:
                busy.append(port)
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # (TIME_WAIT is no user)
        try:
            s.bind(("127.0.0.1", GRPC_PORT))
        except OSError:
            busy.append(GRPC_PORT)
    return busy


def start_sitl(speed_factor: float, log: Path) -> subprocess.Popen:
    with open(log, "w") as fh:
        proc = subprocess.Popen(
            [sys.executable, "-m", "ft_sitl", "sitl", "--no-mqtt", "--speed-factor",
             str(speed_factor), "--tlog", str(log.with_suffix(".tlog"))], cwd=ROOT,
            stdout=fh, stderr=subprocess.STDOUT,
            start_new_session=True)
    deadline = time.time() + 120
    while time.time() < deadline and proc.poll() is None:
        if READY_LINE in log.read_text():
            return proc
        time.sleep(0.2)
    stop(proc)
    raise RuntimeError(f"ft-sitl sitl did not start: {log.read_text()[-500:]}")


def stop(proc: subprocess.Popen | None) -> None:
    """Stop a process this script started, and its children (its own session)."""
    if proc is None or proc.poll() is not None:
        return
    with contextlib.suppress(ProcessLookupError):
        os.killpg(proc.pid, signal.SIGTERM)
    try:
        proc.wait(10)
    except subprocess.TimeoutExpired:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(10)


def needs_server(source: str) -> bool:
    return re.search(r"System\([^)]*mavsdk_server_address", source) is not None


#: the line that names an exception in a traceback
ERROR_LINE = re.compile(r"^[A-Za-z_][\w.]*(Error|Exception|Exit)\b.*")
#: after a traceback, how long an example may stay silent before it counts as stuck:
#: mavsdk_grpc's System keeps a thread on its mavsdk_server alive, so a script whose
#: coroutine raised does not exit by itself
STUCK_AFTER_ERROR_S = 3.0


def run_one(example: Path, examples: Path, timeout: float, speed_factor: float,
            logs: Path | None) -> dict:
    source = example.read_text()
    sitl = server = proc = None
    with tempfile.TemporaryDirectory(prefix="mavsdk-example-") as tmp:
        work = Path(tmp) / "examples"
        shutil.copytree(examples, work)
        script = work / example.relative_to(examples)
        out_path = Path(tmp) / "example.log"
        try:
            sitl = start_sitl(speed_factor, Path(tmp) / "sitl.log")
            if needs_server(source):
                import mavsdk_grpc.bin  # (for the bundled binary's path only)

                binary = Path(mavsdk_grpc.bin.__file__).parent / "mavsdk_server"
                # in the example's directory: the server writes the example's
                # downloads, relative to its own working directory
                server = subprocess.Popen(
                    [str(binary), "-p", str(GRPC_PORT), "udpin://0.0.0.0:14540"],
                    cwd=script.parent, stdout=subprocess.DEVNULL,
                    stderr=subprocess.DEVNULL, start_new_session=True)
            t0 = time.time()
            with open(out_path, "w") as fh:
                proc = subprocess.Popen(
                    [sys.executable, str(Path(__file__).resolve()), "--as-mavsdk",
                     str(script)], cwd=script.parent, stdin=subprocess.PIPE, stdout=fh,
                    stderr=subprocess.STDOUT, start_new_session=True)
            outcome, stuck, elapsed = None, False, 0.0
            size, quiet_since = -1, time.time()
            while outcome is None:
                time.sleep(0.25)
                elapsed = time.time() - t0
                text = out_path.read_text(errors="replace")
                if len(text) != size:
                    size, quiet_since = len(text), time.time()
                if proc.poll() is not None:
                    outcome = "completes" if proc.returncode == 0 else "fails"
                elif "Traceback (most recent call last)" in text and \
                        time.time() - quiet_since > STUCK_AFTER_ERROR_S:
                    outcome, stuck = "fails", True
                    elapsed = quiet_since - t0
                elif elapsed > timeout:
                    outcome = "timeout"
            stop(proc)
            with contextlib.suppress(BrokenPipeError):
                proc.stdin.close()
        finally:
            stop(server)
            stop(sitl)
        out = out_path.read_text(errors="replace") if out_path.exists() else ""
        if logs is not None:
            logs.mkdir(parents=True, exist_ok=True)
            (logs / (example.stem + ".log")).write_text(out)
    lines = [ln for ln in out.splitlines() if ln.strip()]
    errors = [ln for ln in lines if ERROR_LINE.match(ln) and "sys.meta_path is None" not in ln]
    return {"example": str(example.relative_to(examples)), "outcome": outcome,
            "exit": proc.returncode if proc is not None else None,
            "stuck_after_error": stuck, "seconds": round(elapsed, 1),
            "external_server": needs_server(source),
            "error": errors[-1] if errors else "", "tail": lines[-6:]}


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["--as-mavsdk"]:
        as_mavsdk(argv[1], argv[2:])
        return 0
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("examples", type=Path, help="MAVSDK-Python's examples directory")
    ap.add_argument("--only", nargs="*", default=None, help="example file names to run")
    ap.add_argument("--timeout", type=float, default=180.0, help="seconds per example")
    ap.add_argument("--speed-factor", type=float, default=1.0)
    ap.add_argument("--json", type=Path, help="write the results here")
    ap.add_argument("--logs", type=Path, help="keep each example's output in this directory")
    args = ap.parse_args(argv)
    examples = args.examples.resolve()
    scripts = sorted(p for p in examples.rglob("*.py")
                     if args.only is None or p.name in args.only)
    if not scripts:
        ap.error(f"no examples in {examples}")
    busy = ports_free()
    if busy:
        print(f"ports in use: {busy}; stop PX4 SITL / ft-sitl / clients first",
              file=sys.stderr)
        return 2
    results = []
    for script in scripts:
        r = run_one(script, examples, args.timeout, args.speed_factor, args.logs)
        results.append(r)
        what = r["error"] or (r["tail"][-1] if r["tail"] else "")
        stuck = " (did not exit)" if r["stuck_after_error"] else ""
        print(f"| {r['example']} | {r['outcome']}{stuck} | {r['seconds']} s | {what[:140]} |",
              flush=True)
        if args.json:
            args.json.write_text(json.dumps(results, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
