"""The ft-sitl command as a user runs it: the installed console script, real processes (and
the same command function in-process where only its argument parsing is checked)."""

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from ft_sitl.cli import main as cli_main

EXE = shutil.which("ft-sitl", path=str(Path(sys.executable).parent))


def run(*args, check=True):
    assert EXE, "the ft-sitl console script is not installed next to this Python"
    proc = subprocess.run([EXE, *args], capture_output=True, text=True, timeout=300)
    if check:
        assert proc.returncode == 0, proc.stderr
    return proc


def _help(capsys, *args) -> str:
    """A command's --help through the command's own function, in-process."""
    with pytest.raises(SystemExit) as exc:
        cli_main([*args, "--help"])
    assert exc.value.code == 0
    return capsys.readouterr().out


@pytest.mark.e2e
def test_help_lists_every_subcommand(capsys):
    out = run("--help").stdout  # (the installed command, once)
    for cmd in ("demo", "platforms", "params", "campaign", "navigators", "train"):
        assert cmd in out
    assert all(sub in _help(capsys, "platforms") for sub in ("list", "show", "check",
                                                            "generate"))
    for sub in ("list", "show", "check", "generate"):
        assert _help(capsys, "platforms", sub).startswith("usage: ft-sitl platforms")
    assert "--json" in _help(capsys, "platforms", "show")


@pytest.mark.e2e
def test_platforms_list_json_has_the_36_with_recomputed_indicators(table1_rows):
    rows = json.loads(run("platforms", "list", "--json").stdout)
    # the catalog in Table 1 order, then the controlled series (test_cli_platforms_series)
    assert [r["name"] for r in rows[:36]] == [r["name"] for r in table1_rows]
    assert {r["category"] for r in rows[36:]} == {"series"}
    for r, t in zip(rows, table1_rows):
        assert round(r["twr_max"], 1) == float(t["twr_max"])
        assert round(r["alpha_z_max_rad_s2"], 1) == float(t["alpha_z_max_rad_s2"])
    virt = json.loads(run("platforms", "list", "--json", "--category", "virtual").stdout)
    assert len(virt) == 18


@pytest.mark.e2e
def test_platforms_show_text_and_json():
    out = run("platforms", "show", "0.98kg-EGO Planner DIY").stdout
    assert "TWR_max 4.600" in out and "inertia_kg_m2" in out
    data = json.loads(run("platforms", "show", "0.98kg-EGO Planner DIY", "--json").stdout)
    assert data["physical"]["mass_kg"] == 0.98
    assert round(data["indicators"]["alpha_xy_max_rad_s2"], 1) == 1083.3


@pytest.mark.e2e
def test_unknown_platform_is_a_one_line_error_with_suggestions():
    proc = run("platforms", "show", "0.98kg-EGO Planer DIY", check=False)
    assert proc.returncode == 2
    assert proc.stderr.count("\n") == 1
    assert "unknown platform" in proc.stderr and "0.98kg-EGO Planner DIY" in proc.stderr


@pytest.mark.e2e
def test_check_and_use_a_user_platform_file(tmp_path):
    f = tmp_path / "mine.yaml"
    f.write_text("platform:\n  name: mine\n  layout: quad_plus\n  mass_kg: 2.0\n"
                 "  twr_max: 2.5\n  alpha_xy_max_rad_s2: 150\n  alpha_z_max_rad_s2: 9\n")
    assert "ok  mine" in run("platforms", "check", str(f)).stdout
    rows = json.loads(run("platforms", "list", "--json", "--platform-file", str(f)).stdout)
    assert rows[-1]["name"] == "mine" and rows[-1]["category"] == "user"
    bad = tmp_path / "bad.toml"
    bad.write_text('[platform]\nname = "x"\nlayout = "quad_x"\nmass_kg = 1\ntwr_max = 3\n'
                   'alpha_xy_max_rad_s2 = 100\nalpha_z_max_rad_s2 = 8\ncolour = "red"\n')
    proc = run("platforms", "check", str(bad), check=False)
    assert proc.returncode == 2 and "'colour'" in proc.stderr and str(bad) in proc.stderr


@pytest.mark.e2e
def test_generate_is_reproducible_and_writes_a_loadable_file(tmp_path):
    a = run("platforms", "generate", "--count", "3", "--seed", "4", "--json").stdout
    b = run("platforms", "generate", "--count", "3", "--seed", "4", "--json").stdout
    assert a == b and len(json.loads(a)) == 3
    out = tmp_path / "gen.toml"
    run("platforms", "generate", "--count", "3", "--seed", "4", "--out", str(out))
    assert "ok" in run("platforms", "check", str(out)).stdout
    proc = run("platforms", "generate", "--out", str(out), check=False)
    assert proc.returncode == 2 and "exists" in proc.stderr


@pytest.mark.e2e
def test_params_list_json():
    rows = {r["name"]: r for r in json.loads(run("params", "list", "--json").stdout)}
    assert rows["MPC_XY_VEL_MAX"]["default"] == 4.0
    assert rows["MPC_TILTMAX_AIR"]["max"] == 89.0
    assert rows["MPC_XY_VEL_MAX"]["status"] == "honoured" and rows["MPC_XY_VEL_MAX"]["honoured"]
    rcl = rows["COM_RC_OVERRIDE"]
    assert (rcl["status"], rcl["honoured"], rcl["type"], rcl["default"], rcl["min"],
            rcl["max"]) == ("stored", False, "INT32", 1, 0, 3)
    assert rows["COM_OBL_RC_ACT"]["min"] is None  # PX4 publishes no range
    assert sum(r["honoured"] for r in rows.values()) == 80 and len(rows) == 479


def test_params_filters_and_show(capsys):
    """In-process (main()): the command's other forms, without a process each."""
    from ft_sitl.cli import main  # (in-process: the rest of this module runs ft-sitl itself)

    def out(*argv, status=0):
        assert main(list(argv)) == status
        return capsys.readouterr()

    honoured = json.loads(out("params", "list", "--json", "--honoured").out)
    stored = json.loads(out("params", "list", "--json", "--stored").out)
    assert {r["status"] for r in honoured} == {"honoured"} and len(honoured) == 80
    assert {r["status"] for r in stored} == {"stored"} and len(stored) == 479 - 80
    lines = out("params", "list").out.splitlines()
    assert lines[0].split()[:3] == ["MPC_XY_VEL_MAX", "honoured", "4"]
    rcl = next(ln for ln in lines if ln.startswith("COM_RC_OVERRIDE "))
    assert rcl.split()[1:4] == ["stored", "1", "[0,"]
    text = out("params", "show", "MPC_ACC_HOR_MAX").out
    assert "honoured" in text and "PX4 v1.15.2: default 5, range [2, 15] m/s^2" in text
    data = json.loads(out("params", "show", "MPC_XY_TRAJ_P", "--json").out)
    assert (data["status"], data["default"], data["max"]) == ("stored", 0.5, 1.0)
    assert data["px4"]["release"] == "v1.15.2" and data["px4"]["differs"] == []
    err = out("params", "show", "COM_RCL_EXCPT", status=2).err
    assert err.count("\n") == 1 and err.startswith(
        "ft-sitl: error: unknown parameter 'COM_RCL_EXCPT'; did you mean 'COM_RCL_EXCEPT'")
    with pytest.raises(SystemExit) as exc:
        main(["params", "list", "--honoured", "--stored"])
    assert exc.value.code == 2 and "not allowed with" in capsys.readouterr().err


@pytest.mark.e2e
def test_demo_flies_and_lands(tmp_path):
    png = tmp_path / "demo.png"
    data = json.loads(run("demo", "--json", "--plot", str(png)).stdout)
    assert data["landed"] is True
    names = [p["name"] for p in data["phases"]]
    assert names == ["arm", "takeoff", "leg", "turn", "descend", "disarm"]
    leg = data["phases"][2]
    assert leg["end_position_enu_m"][0] == pytest.approx(8.0, abs=0.3)
    assert leg["max_speed_m_s"] <= 4.0 * 1.05
    assert data["max_impact_speed_m_s"] < 1.0
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.e2e
def test_bad_arguments_exit_2():
    assert run("platforms", "generate", "--count", "zero", check=False).returncode == 2
    assert run("nonsense", check=False).returncode == 2


@pytest.mark.e2e
def test_sitl_serves_prints_urls_and_stops_cleanly_on_ctrl_c(tmp_path):
    import signal
    import time

    from pymavlink import mavutil

    log = tmp_path / "run.tlog"
    proc = subprocess.Popen([EXE, "sitl", "--instances", "2", "--json", "--tlog", str(log)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        head = ""
        while True:
            line = proc.stdout.readline()
            assert line, proc.stderr.read()
            head += line
            if line.startswith("}"):  # the closing brace of the top-level object
                break
        info = json.loads(head)
        assert [v["mavsdk"] for v in info["vehicles"]] == ["udpin://0.0.0.0:14540",
                                                           "udpin://0.0.0.0:14541"]
        c = mavutil.mavlink_connection("udpin:127.0.0.1:14541", source_system=246)
        hb = c.wait_heartbeat(timeout=10)
        assert hb is not None and hb.get_srcSystem() == 2
        time.sleep(0.5)
    finally:
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=20)
    assert proc.returncode == 0, err
    assert "achieved speed factor" in err and "Traceback" not in err
    assert log.stat().st_size > 1000


# (arguments, what the one-line error says): every numeric option of sitl, both bridges and
# navigate is checked as it is parsed (ft_sitl.cli.common.number)
BAD_NUMBERS = [
    (["sitl", "--duration", "nan"], "--duration: nan is not a finite number"),
    (["sitl", "--duration", "-5"], "--duration: -5 must be more than 0"),
    (["sitl", "--duration", "inf"], "--duration: inf is not a finite number"),
    (["sitl", "--speed-factor", "nan"], "--speed-factor: nan is not a finite number"),
    (["sitl", "--speed-factor", "2000"], "--speed-factor: 2000 must be within 0.01..1000"),
    (["sitl", "--telemetry-rate", "inf"], "--telemetry-rate: inf is not a finite number"),
    (["sitl", "--instance", "-1"], "--instance: -1 must be within 0..999"),
    (["sitl", "--instances", "2.5"], "--instances: '2.5' is not an integer"),
    (["sitl", "--wind-seed", "-3"], "--wind-seed: -3 must be at least 0"),
    (["bridge", "px4", "--duration", "nan"], "--duration: nan is not a finite number"),
    (["bridge", "px4", "--speed-factor=-inf"], "--speed-factor: -inf is not a finite number"),
    (["bridge", "px4", "--instance", "1000"], "--instance: 1000 must be within 0..999"),
    (["bridge", "ardupilot", "--speed-factor", "0"], "--speed-factor: 0 must be within"),
    (["bridge", "ardupilot", "--port", "70000"], "--port: 70000 must be within 1..65535"),
    (["navigate", "--algorithm", "straight", "--speed-factor", "nan"],
     "--speed-factor: nan is not a finite number"),
    (["navigate", "--algorithm", "straight", "--max-speed", "0"],
     "--max-speed: 0 must be within 0.1..20"),
    (["navigate", "--algorithm", "straight", "--timeout", "inf"],
     "--timeout: inf is not a finite number"),
    (["navigate", "--algorithm", "straight", "--connect-timeout", "-1"],
     "--connect-timeout: -1 must be more than 0"),
    (["navigate", "--algorithm", "straight", "--heading", "nan"],
     "--heading: nan is not a finite number"),
    (["sitl", "--instance", "any"], "--instance: 'any' is neither an integer nor auto"),
]


@pytest.mark.e2e
def test_non_finite_and_out_of_range_numbers_are_one_line_errors(capsys):
    # `sitl --duration nan` used to serve forever and `--duration -5` to exit 0 at once.
    # The real command for one case of each command (in parallel: each start costs a
    # second), the parser in this process for all of them
    assert EXE
    real = [BAD_NUMBERS[i] for i in (0, 1, 9, 13, 14)] + [
        (["sitl", "--home", "nan,8.5,488"], "--home: home latitude: nan")]
    procs = [subprocess.Popen([EXE, *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                              text=True) for args, _ in real]
    for (args, needle), proc in zip(real, procs):
        try:
            _, err = proc.communicate(timeout=60)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.communicate()
            raise AssertionError(f"{args} did not stop") from None
        assert proc.returncode == 2, (args, err)
        assert err.startswith(f"ft-sitl: error: {needle}") and err.count("\n") == 1, err
    from ft_sitl.cli import main

    for args, needle in BAD_NUMBERS:
        assert main(args) == 2, args
        err = capsys.readouterr().err
        assert err.startswith(f"ft-sitl: error: {needle}") and err.count("\n") == 1, err


@pytest.mark.e2e
def test_mavsdk_is_a_dependency_and_its_absence_is_one_line(tmp_path):
    # the README's first command installs no extra, yet `navigate` and `campaign run
    # --transport mavlink` fly MAVSDK clients: it is a core dependency, and if it cannot be
    # imported all the same, the command says what to install before it starts
    import tomllib

    project = tomllib.loads((Path(__file__).resolve().parents[2] / "pyproject.toml")
                            .read_text())["project"]
    assert any(d.startswith("mavsdk>=") for d in project["dependencies"])
    stub = tmp_path / "stub" / "mavsdk"
    stub.mkdir(parents=True)
    (stub / "__init__.py").write_text(
        "raise ModuleNotFoundError(\"No module named 'mavsdk'\", name='mavsdk')\n")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        [str(stub.parent), *filter(None, [os.environ.get("PYTHONPATH")])])}
    for args in (["navigate", "--algorithm", "straight", "--goal", "5,0,-2"],
                 ["campaign", "run", "quick", "--transport", "mavlink", "--limit", "1",
                  "--out", str(tmp_path / "out")]):
        proc = subprocess.run([EXE, *args], capture_output=True, text=True, env=env,
                              timeout=120)
        assert proc.returncode == 2, (args, proc.stderr)
        assert proc.stderr.startswith("ft-sitl: error: the MAVSDK client needs the Python "
                                      "package 'mavsdk'"), proc.stderr
        assert "pip install 'mavsdk>=4.1'" in proc.stderr and proc.stderr.count("\n") == 1
    assert not (tmp_path / "out").exists()


@pytest.mark.e2e
def test_bridge_spawn_heading_is_north_unless_given():
    out = run("bridge", "px4", "--spawn-yaw", "45", "--duration", "0.3", "--instance", "777")
    assert "no scenario, spawn heading 45.0 deg" in out.stdout.splitlines()[0]
    out = run("bridge", "px4", "--duration", "0.3", "--instance", "777")
    assert "no scenario, spawn heading 0.0 deg" in out.stdout.splitlines()[0]
    proc = run("bridge", "ardupilot", "--spawn-yaw", "400", check=False)
    assert proc.returncode == 2
    assert proc.stderr == "ft-sitl: error: --spawn-yaw: 400 must be within -360..360\n"


@pytest.mark.e2e
def test_sitl_bad_arguments_are_one_line_errors():
    for args, needle in ((["--home", "1,2"], "--home"), (["--home", "95,0,0"], "latitude"),
                         (["--instances", "0"], "--instances"), (["--speed-factor", "0"],
                                                                 "--speed-factor"),
                         (["--bind", "localhost:1"], "--bind")):
        proc = run("sitl", "--duration", "1", *args, check=False)
        assert proc.returncode == 2, (args, proc.stderr)
        assert needle in proc.stderr and proc.stderr.count("\n") == 1
