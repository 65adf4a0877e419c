"""The pytest plugin (ft_sitl_pytest) as a user meets it: pytest run on test files in a
fresh directory (pytest's pytester, in a child process), with real ft-sitl sitl processes
and real MAVLink clients."""

import re
import subprocess
import sys
import xml.etree.ElementTree as ET

import pytest

pytest_plugins = ["pytester"]

# a user's test file: one test fails after talking to its vehicle, one passes
FAILING = '''
from pymavlink import mavutil

def test_climbs_higher_than_it_can(ft_sitl_vehicle):
    link = mavutil.mavlink_connection(ft_sitl_vehicle.pymavlink_url, source_system=245,
                                      source_component=190)
    try:
        assert link.wait_heartbeat(timeout=120) is not None
        pos = link.recv_match(type="LOCAL_POSITION_NED", blocking=True, timeout=120)
    finally:
        link.close()
    assert -pos.z > 100, "still on the ground"

def test_passes(ft_sitl_vehicle):
    assert ft_sitl_vehicle.sysid == 1
'''


def _section(stdout: str) -> list[str]:
    lines = stdout.splitlines()
    start = next(i for i, ln in enumerate(lines) if re.match(r"^-+ ft-sitl flight -+$", ln))
    out = []
    for ln in lines[start + 1:]:
        if ln.startswith(("=", "_")) or re.match(r"^-+ .* -+$", ln):
            break
        out.append(ln)
    return out


@pytest.mark.e2e
def test_a_failing_test_gets_its_tlog_and_trajectory_plot(pytester):
    pytester.makepyfile(test_user=FAILING)
    logs = pytester.path / "vehicle-logs"
    result = pytester.runpytest_subprocess("--ft-sitl-logs", str(logs), "--junitxml=out.xml",
                                           "-p", "no:cacheprovider")
    result.assert_outcomes(passed=1, failed=1)
    result.stdout.fnmatch_lines(["*AssertionError: still on the ground*"])
    section = _section(result.stdout.str())
    files = {}
    for ln in section:
        m = re.match(r"^\s+(telemetry log|trajectory plot|process log):\s+(\S+)", ln)
        if m:
            files[m.group(1)] = m.group(2)
    assert set(files) == {"telemetry log", "trajectory plot", "process log"}, section
    tlog, png, log = (pytester.path / files[k] for k in
                      ("telemetry log", "trajectory plot", "process log"))
    assert tlog.parent == png.parent == log.parent
    assert tlog.parent.parent == logs
    assert tlog.parent.name == "test_user.py_test_climbs_higher_than_it_can"
    assert tlog.stat().st_size > 1000
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # the log closed by a clean stop: the process's exit summary is in it
    assert "achieved speed factor" in log.read_text()
    assert any(ln.strip().startswith("vehicle sysid 1: ") and "positions over" in ln
               for ln in section), section
    # the command that serves the same vehicle by hand, without the plugin's own options
    assert "  serve again:     ft-sitl sitl --instances=1 --instance auto --no-mqtt" in section
    # the passing test's files are not kept
    assert sorted(p.name for p in logs.iterdir()) == [tlog.parent.name]
    # JUnit XML (what CI services show) carries the paths as the test case's properties
    case = next(c for c in ET.parse(pytester.path / "out.xml").iter("testcase")
                if c.get("name") == "test_climbs_higher_than_it_can")
    props = {p.get("name"): p.get("value") for p in case.iter("property")}
    assert props == {"ft_sitl_tlog": str(tlog), "ft_sitl_log": str(log),
                     "ft_sitl_trajectory": str(png)}


OPTIONS = '''
import time

import pytest
from pymavlink import mavutil

def first(url, kind):
    link = mavutil.mavlink_connection(url, source_system=245, source_component=190)
    try:
        return link.recv_match(type=kind, blocking=True, timeout=120)
    finally:
        link.close()

@pytest.mark.ft_sitl(home=(52.52, 13.405, 34.0))
def test_marker_home(ft_sitl_vehicle):
    m = first(ft_sitl_vehicle.pymavlink_url, "HOME_POSITION")
    assert (m.latitude, m.longitude, m.altitude) == (525200000, 134050000, 34000)

@pytest.mark.parametrize("ft_sitl_vehicle", [{"home": "-33.86,151.21,5"}], indirect=True)
def test_param_home(ft_sitl_vehicle):
    m = first(ft_sitl_vehicle.pymavlink_url, "HOME_POSITION")
    assert (m.latitude, m.longitude) == (-338600000, 1512100000)

@pytest.mark.ft_sitl(vehicles=3)
def test_fleet(ft_sitl_fleet):
    assert [v.sysid for v in ft_sitl_fleet] == [1, 2, 3]
    numbers = [v.instance for v in ft_sitl_fleet]
    assert numbers == list(range(numbers[0], numbers[0] + 3))
    for v in ft_sitl_fleet:
        assert v.ports.client == 14540 + v.instance
        assert v.mavsdk_url == f"udpin://0.0.0.0:{v.ports.client}"
        assert first(v.pymavlink_url, "HEARTBEAT").get_srcSystem() == v.sysid

@pytest.mark.ft_sitl(pace="client", pace_span=0.05)
def test_client_paced(ft_sitl_vehicle):
    # the clock runs at most 50 ms past a client's last message: after one heartbeat, a
    # wall second of telemetry spans at most that (wall pacing would give about 1 s)
    link = mavutil.mavlink_connection(ft_sitl_vehicle.pymavlink_url, source_system=245,
                                      source_component=190)
    try:
        assert link.wait_heartbeat(timeout=120) is not None
        link.mav.heartbeat_send(6, 8, 0, 0, 0)
        times = []
        end = time.monotonic() + 1.0
        while time.monotonic() < end:
            m = link.recv_match(type="ATTITUDE", blocking=True, timeout=0.2)
            if m is not None:
                times.append(m.time_boot_ms)
    finally:
        link.close()
    assert times, "the clock did not move after the message"
    assert max(times) - min(times) <= 50 + 4 + 10, times  # span + a chunk + one period

@pytest.mark.ft_sitl(pace_span=0.1)
def test_span_without_client_pacing(ft_sitl_vehicle):
    pass

@pytest.mark.ft_sitl(speed_fctor=2)
def test_misspelt(ft_sitl_vehicle):
    pass

@pytest.mark.ft_sitl(speed_factor=0)
def test_out_of_range(ft_sitl_vehicle):
    pass

@pytest.mark.ft_sitl(vehicles=2)
def test_one_is_one(ft_sitl_vehicle):
    pass
'''


@pytest.mark.e2e
def test_options_reach_the_vehicles_and_bad_ones_are_one_line_errors(pytester, monkeypatch):
    pytester.makepyfile(test_options=OPTIONS)
    monkeypatch.setenv("COLUMNS", "400")  # the summary's lines whole
    result = pytester.runpytest_subprocess("-p", "no:cacheprovider", "-rE")
    result.assert_outcomes(passed=4, errors=4)
    out = result.stdout.str()
    assert ("ERROR test_options.py::test_misspelt - Failed: ft_sitl_vehicle: ft-sitl vehicles "
            "'test_options.py::test_misspelt': unknown option 'speed_fctor' (options: "
            "platform, ") in out
    # the range is the command's: its one-line error, quoted from the process's log
    result.stdout.fnmatch_lines([
        "*ft_sitl_vehicle: ft-sitl vehicles 'test_options.py::test_out_of_range': ft-sitl "
        "sitl exited with status 2 before serving:*",
        "ft-sitl: error: --speed-factor: 0 must be within 0.01..1000",
    ])
    assert ("ft-sitl: error: --pace-span: 0.1 is only for --pace client (wall pacing has no "
            "span)") in out
    assert ("ERROR test_options.py::test_one_is_one - Failed: ft_sitl_vehicle: it serves "
            "one vehicle, not vehicles=2: use ft_sitl_fleet") in out
    assert "During handling" not in out


TWO_WORKERS = '''
import os
import time
from pathlib import Path

import pytest

@pytest.mark.parametrize("k", range(4))
def test_vehicle(ft_sitl_vehicle, k):
    me = os.environ["PYTEST_XDIST_WORKER"]
    other = {"gw0": "gw1", "gw1": "gw0"}[me]
    Path(f"seen-{k}-{me}-{ft_sitl_vehicle.instance}").touch()
    # each worker's first test waits here, holding its vehicle, until the other worker has
    # one too: the two first vehicles are served at the same time
    deadline = time.monotonic() + 600
    while not list(Path().glob(f"seen-*-{other}-*")):
        assert time.monotonic() < deadline, "the other worker never served a vehicle"
        time.sleep(0.1)
'''


@pytest.mark.e2e
def test_xdist_workers_get_different_instances(pytester):
    pytester.makepyfile(test_two=TWO_WORKERS)
    result = pytester.runpytest_subprocess("-p", "no:cacheprovider", "-n", "2",
                                           "--dist", "load")
    result.assert_outcomes(passed=4)
    seen = sorted(tuple(p.name.split("-")[1:]) for p in pytester.path.glob("seen-*"))
    assert len(seen) == 4 and {w for _, w, _ in seen} == {"gw0", "gw1"}, seen
    # each worker's first vehicle was served while the other's was: their numbers differ
    first = {}
    for _, w, inst in sorted(seen, key=lambda s: int(s[0])):
        first.setdefault(w, inst)
    assert first["gw0"] != first["gw1"], seen


@pytest.mark.e2e
def test_loading_the_plugin_imports_no_ft_sitl_numpy_or_pymavlink():
    code = ("import sys, pytest; from importlib.metadata import entry_points; "
            "ep, = [e for e in entry_points(group='pytest11') if e.name == 'ft_sitl']; "
            "ep.load(); print(sorted(m for m in ('ft_sitl', 'numpy', 'numba', 'pymavlink', "
            "'matplotlib') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, timeout=120).stdout
    assert out.strip() == "[]"
