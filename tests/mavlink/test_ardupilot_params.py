""".parm files on the ArduCopter face: read as ArduPilot SITL's --defaults reads them
(NAME VALUE / NAME,VALUE, # comments, later files win), refused in one line naming file,
line, name and range; `ft-sitl sitl --autopilot ardupilot --defaults A,B` sets them in the
vehicle (read back over the wire); MAVProxy's `param save` writes a file that reads back
with the vehicle's values."""

import json
import subprocess
import sys
import time

import pytest
from pymavlink import mavutil

from ft_sitl.autopilot.params import ParamSet
from ft_sitl.mavlink.ardupilot import parm
from ft_sitl.mavlink.ardupilot.parameters import STATUSTEXT_LEN, refusal_text
from ft_sitl.mavlink.ardupilot.params import AP_PARAMS, FLOAT, ApParamSet

from .ardupilot_harness import free_ardupilot_sitl, mavproxy_session


def test_a_parm_file_reads_with_spaces_commas_tabs_and_comments(tmp_path):
    f = tmp_path / "a.parm"
    f.write_text("# a comment\n\nWPNAV_SPEED 750\nANGLE_MAX,4500.4  # rounded\n"
                 "RTL_ALT\t2000\n  FENCE_RADIUS , 150.5\n")
    assert [(n, v, k) for n, v, k in parm.read(f)] == [
        ("WPNAV_SPEED", 750.0, 3), ("ANGLE_MAX", 4500, 4), ("RTL_ALT", 2000, 5),
        ("FENCE_RADIUS", 150.5, 6)]
    g = tmp_path / "b.parm"
    g.write_text("WPNAV_SPEED 900\n")
    assert [(n, v, w) for n, v, w in parm.read_all(f"{f},{g}")][-1] == \
        ("WPNAV_SPEED", 900.0, f"{g}:1")


@pytest.mark.parametrize("text, message", [
    ("WPNAV_SPEED 750\nWPNAV_SPED 700\n", ":2: unknown parameter 'WPNAV_SPED'"),
    ("ANGLE_MAX 9000\n", ":1: ANGLE_MAX: 9000 cdeg is outside [1000, 8000] cdeg"),
    ("FENCE_ENABLE\n", ":1: expected NAME VALUE"),
    ("RTL_ALT 1 2\n", ":1: expected NAME VALUE"),
    ("RTL_ALT fast\n", ":1: RTL_ALT: 'fast' is not a number"),
    ("RTL_ALT nan\n", ":1: RTL_ALT: nan is not finite"),
])
def test_a_bad_parm_file_is_refused_in_one_line_naming_file_and_line(tmp_path, text, message):
    f = tmp_path / "bad.parm"
    f.write_text(text)
    with pytest.raises(parm.ParmError) as e:
        parm.read(f)
    assert str(e.value).startswith(f"{f}{message}"), str(e.value)
    assert "\n" not in str(e.value)
    with pytest.raises(parm.ParmError, match="cannot read"):
        parm.read(tmp_path / "none.parm")


def test_defaults_and_types_arducopter_has():
    """The parity run's findings: FS_OPTIONS 16 (GCS_CONTINUE_IF_PILOT_CONTROL),
    BATT_LOW_MAH/BATT_CRT_MAH floats (AP_BattMonitor_Params' AP_Float: REAL32)."""
    assert AP_PARAMS["FS_OPTIONS"].default == 16
    assert AP_PARAMS["BATT_LOW_MAH"].ptype == FLOAT and AP_PARAMS["BATT_CRT_MAH"].ptype == FLOAT
    assert not AP_PARAMS["BATT_LOW_MAH"].is_int


def test_a_refusal_fits_one_statustext():
    for name, spec in AP_PARAMS.items():
        for value in (-1.234567e300, spec.hi + 1e9, (spec.lo + spec.hi) / 2):
            text = refusal_text(name, value)
            assert len(text) <= STATUSTEXT_LEN and text.startswith(name), text
    assert refusal_text("WPNAV_SPEED", 1e6) == "WPNAV_SPEED: 1e+06 not in 10..2000 cm/s"


def test_written_parameters_read_back_identical(tmp_path):
    ap = ApParamSet(ParamSet(), sysid=1)
    ap.set("WPNAV_SPEED", 650)
    ap.set("PSC_VELXY_P", 2.5)
    f = tmp_path / "out.parm"
    parm.write(f, ap)
    back = {n: v for n, v, _ in parm.read(f)}
    assert back == dict(ap.items())


def _param(conn, name: str) -> float:
    deadline = time.time() + 30
    while time.time() < deadline:
        conn.param_fetch_one(name)
        m = conn.recv_match(type="PARAM_VALUE", blocking=True, timeout=2)
        if m is not None and m.param_id == name:
            return m.param_value
    raise AssertionError(f"no PARAM_VALUE of {name}")


@pytest.mark.e2e  # (tests/lanes.py: a SITL process)
def test_cli_defaults_sets_the_files_parameters_later_files_winning(tmp_path):
    a, b = tmp_path / "a.parm", tmp_path / "b.parm"
    a.write_text("WPNAV_SPEED 700\nRTL_ALT 2500  # cm\n")
    b.write_text("WPNAV_SPEED,850\n")
    proc = subprocess.Popen(
        [sys.executable, "-m", "ft_sitl", "sitl", "--autopilot", "ardupilot", "--instance",
         "auto", "--no-mqtt", "--json", "--defaults", f"{a},{b}", "--duration", "60"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=tmp_path)
    try:
        text = ""
        while not text.rstrip().endswith("}") or text.count("{") != text.count("}"):
            line = proc.stdout.readline()
            assert line, proc.stderr.read()
            text += line
        port = json.loads(text)["vehicles"][0]["ports"]["serial"][0]
        mavutil.set_dialect("ardupilotmega")
        conn = mavutil.mavlink_connection(f"tcp:127.0.0.1:{port}", source_system=250)
        try:
            conn.wait_heartbeat(timeout=30)
            assert _param(conn, "WPNAV_SPEED") == 850.0
            assert _param(conn, "RTL_ALT") == 2500.0
            assert _param(conn, "WPNAV_ACCEL") == 250.0  # (untouched: the default)
        finally:
            conn.close()
    finally:
        proc.kill()
        proc.wait(10)


@pytest.mark.e2e
def test_cli_refuses_a_bad_defaults_file_in_one_line(tmp_path):
    bad = tmp_path / "bad.parm"
    bad.write_text("WPNAV_SPEED 750\n\nWPNAV_SPEED 5\n")
    r = subprocess.run([sys.executable, "-m", "ft_sitl", "sitl", "--autopilot", "ardupilot",
                        "--instance", "auto", "--no-mqtt", "--defaults", str(bad),
                        "--duration", "0.5"], capture_output=True, text=True, timeout=120,
                       cwd=tmp_path)
    assert r.returncode != 0
    line = r.stderr.strip().splitlines()[-1]
    assert f"--defaults: {bad}:3: WPNAV_SPEED: 5 cm/s is outside [10, 2000] cm/s" in line, \
        r.stderr
    ok = tmp_path / "ok.parm"
    ok.write_text("WPNAV_SPEED 700\n")
    r = subprocess.run([sys.executable, "-m", "ft_sitl", "sitl", "--instance", "auto",
                        "--no-mqtt", "--defaults", str(ok), "--duration", "0.5"],
                       capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert r.returncode != 0 and "--defaults: only with --autopilot ardupilot" in r.stderr


def test_a_value_the_controller_cannot_fly_names_where_it_came_from(tmp_path):
    f = tmp_path / "slow.parm"
    f.write_text("# slow\nWPNAV_SPEED 100\n")  # ArduCopter takes it; MPC_XY_CRUISE not
    ap = ApParamSet(ParamSet(), sysid=1)
    with pytest.raises(parm.ParmError) as e:
        parm.apply(parm.read_all(str(f)), ap)
    assert str(e.value).startswith(f"{f}:2: WPNAV_SPEED: 100 is outside what ft-sitl flies")
    assert ap["WPNAV_SPEED"] == 1000  # nothing changed


@pytest.mark.e2e  # (a MAVProxy process, TCP)
def test_mavproxy_param_save_writes_a_file_defaults_reads_back(tmp_path):
    with free_ardupilot_sitl() as (server, k):
        agent = server.agents[0]
        ap = agent.vehicle.ap_params
        agent.parameters.set("WPNAV_SPEED", 640)
        agent.parameters.set("PSC_VELXY_P", 2.5)
        saved = tmp_path / "saved.parm"
        with mavproxy_session(k, tmp_path) as mp:
            mp.type(f"param save {saved}")
            mp.until(lambda: saved.exists() and
                     len(saved.read_text().splitlines()) == len(dict(ap.items())), 30,
                     "param save")
        back = {n: v for n, v, _ in parm.read(saved)}
        assert back["WPNAV_SPEED"] == 640 and back["PSC_VELXY_P"] == 2.5
        assert set(back) == set(dict(ap.items()))
        for n, v in ap.items():
            assert back[n] == pytest.approx(v, rel=1e-6, abs=1e-6), n
