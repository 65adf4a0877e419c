"""The lanes (tests/lanes.py): the guard that fails a unit-lane test that opens a network
socket or starts a process, and the marks' registration."""

import os
import socket
import subprocess
import sys
import textwrap
import threading
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from . import lanes

ROOT = Path(__file__).resolve().parents[1]


def test_the_guard_hears_network_sockets_and_processes_of_the_tests_threads(tmp_path):
    before = threading.Event()
    go = threading.Event()
    done = []

    def bind_when_told():  # a thread that was running before: not the test's
        before.set()
        go.wait(10)
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
        done.append(True)

    old = threading.Thread(target=bind_when_told, daemon=True)
    old.start()
    before.wait(10)
    with lanes.watching() as seen:
        go.set()
        old.join(10)
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            s.sendto(b"x", ("127.0.0.1", 9))
        a, b = socket.socketpair()  # Unix-domain: allowed
        a.close(), b.close()
        with socket.socket(socket.AF_UNIX) as s:
            s.bind(str(tmp_path / "sock"))
        sys.audit("subprocess.Popen", "prog", ["prog", "--flag"], None, None)  # as Popen does
        def connect():  # a thread the test starts: the test's (a server of a harness)
            with socket.socket() as s:
                s.connect_ex(("127.0.0.1", 9))

        new = threading.Thread(target=connect)
        new.start()
        new.join(10)
    assert done == [True]
    assert [s.split(" ", 1)[0] for s in seen] == [
        "socket.bind", "socket.sendto", "subprocess.Popen", "socket.connect"], seen
    assert seen[2] == "subprocess.Popen ['prog', '--flag']"


def test_watches_nest():
    with lanes.watching() as outer:
        with lanes.watching() as inner:
            with socket.socket() as s:
                s.bind(("127.0.0.1", 0))
        assert len(inner) == 1 and outer == []  # the inner watch took it
    # (and this test's own watch, the guard's, saw nothing: it passes)


SUITE = '''
import socket, subprocess, sys, threading
import pytest


@pytest.fixture(scope="module")
def server():
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    yield s
    s.close()


def test_binds():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))


def test_spawns():
    subprocess.run([sys.executable, "-c", "pass"], check=True)


def test_a_server_thread_binds():
    t = threading.Thread(target=lambda: socket.socket().bind(("127.0.0.1", 0)))
    t.start()
    t.join()


def test_uses_a_server_fixture(server):
    pass


@pytest.mark.e2e
def test_marked_binds_and_spawns():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
    subprocess.run([sys.executable, "-c", "pass"], check=True)


def test_quiet():
    a, b = socket.socketpair()
    a.close(), b.close()
'''


@pytest.mark.e2e  # (it runs pytest in a child process)
def test_an_unmarked_test_that_binds_or_spawns_fails_and_a_marked_one_passes(tmp_path):
    (tmp_path / "test_suite.py").write_text(textwrap.dedent(SUITE))
    (tmp_path / "conftest.py").write_text(
        "from tests.lanes import pytest_runtest_call, pytest_runtest_setup  # noqa: F401\n")
    (tmp_path / "pytest.ini").write_text("[pytest]\nmarkers =\n    e2e: end to end\n")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        p for p in (str(ROOT), os.environ.get("PYTHONPATH", "")) if p)}
    proc = subprocess.run([sys.executable, "-m", "pytest", "-p", "no:cacheprovider", "-q",
                           "--junit-xml", str(tmp_path / "out.xml"), str(tmp_path)],
                          cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
    outcome = {}
    for case in ET.parse(tmp_path / "out.xml").iter("testcase"):
        kinds = [child.tag for child in case if child.tag in ("failure", "error")]
        text = "".join(child.get("message", "") + (child.text or "") for child in case)
        outcome[case.get("name")] = (kinds[0] if kinds else "passed", text)
    assert {k: v[0] for k, v in outcome.items()} == {
        "test_binds": "failure", "test_spawns": "failure", "test_a_server_thread_binds":
        "failure", "test_uses_a_server_fixture": "error", "test_marked_binds_and_spawns":
        "passed", "test_quiet": "passed"}, proc.stdout[-3000:]
    assert "but opened a network socket or started a process" in outcome["test_binds"][1]
    assert "socket.bind ('127.0.0.1', 0)" in outcome["test_binds"][1]
    assert "mark it @pytest.mark.e2e" in outcome["test_binds"][1]
    assert f"subprocess.Popen {[sys.executable, '-c', 'pass']!r}" in outcome["test_spawns"][1]


def test_the_marks_are_registered_and_checked():
    import tomllib

    ini = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["pytest"]["ini_options"]
    assert sorted(m.split(":")[0] for m in ini["markers"]) == ["e2e", "slow"]
    assert "--strict-markers" in ini["addopts"]
