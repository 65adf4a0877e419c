"""QGC WPL 110 .waypoints files: read and written by ft_sitl.mavlink.ardupilot.waypoints,
read by pymavlink's own MAVWPLoader, loaded by `ft-sitl sitl --autopilot ardupilot
--mission` and written back by --mission-out; bad files answered with one line naming the
line."""

import os
import subprocess
import sys

import pytest

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil, mavwp  # noqa: E402

from ft_sitl.mavlink.ardupilot import waypoints  # noqa: E402

MISSION = """QGC WPL 110
0\t1\t0\t16\t0\t0\t0\t0\t47.397742\t8.545594\t488.0\t1
1\t0\t3\t22\t0\t0\t0\t0\t0\t0\t10\t1
2\t0\t3\t16\t2\t0\t0\t0\t47.3979\t8.5457\t12.5\t1
3\t0\t3\t177\t2\t1\t0\t0\t0\t0\t0\t1
4\t0\t3\t21\t0\t0\t0\t0\t0\t0\t0\t1
"""


def test_round_trip_and_pymavlink_reads_what_we_write(tmp_path):
    items = waypoints.parse(MISSION, "m.waypoints")
    assert [it.command for it in items] == [16, 22, 16, 177, 21]
    assert items[2].x == 473979000 and items[2].param1 == 2.0 and items[2].z == 12.5
    out = tmp_path / "out.waypoints"
    waypoints.write(out, items)
    assert [(it.command, it.x, it.y, it.z) for it in waypoints.read(out)] == \
        [(it.command, it.x, it.y, it.z) for it in items]
    mavutil.set_dialect("ardupilotmega")
    loader = mavwp.MAVWPLoader()
    assert loader.load(str(out)) == 5
    w = loader.wp(2)
    assert abs(w.x - 47.3979) < 1e-7 and w.command == 16 and w.frame == 3


@pytest.mark.parametrize("text, message", [
    ("QGC WPL 100\n", "m.waypoints:1: the first line must be 'QGC WPL 110'"),
    ("QGC WPL 110\n0\t1\t0\t16\t0\n", "m.waypoints:2: 5 fields, a QGC WPL 110 item has 12"),
    (MISSION.replace("2\t0\t3\t16", "7\t0\t3\t16"), "m.waypoints:4: index 7, expected 2"),
    (MISSION.replace("3\t0\t3\t177", "3\t0\t9\t177"), "m.waypoints:5: frame 9 is not "
                                                      "supported"),
    (MISSION.replace("\t12.5\t", "\tx\t"), "m.waypoints:4: index, current, frame"),
    ("QGC WPL 110\n", "m.waypoints:1: no items"),
])
def test_bad_files_name_the_line(text, message):
    with pytest.raises(waypoints.WaypointsError) as e:
        waypoints.parse(text, "m.waypoints")
    assert str(e.value).startswith(message) and "\n" not in str(e.value)


def _sitl(*args, cwd):
    return subprocess.run([sys.executable, "-m", "ft_sitl", "sitl", "--autopilot",
                           "ardupilot", "--instance", "auto", "--no-mqtt", *args],
                          capture_output=True, text=True, timeout=120, cwd=cwd)


@pytest.mark.e2e  # (tests/lanes.py: a SITL process)
def test_cli_loads_a_mission_file_and_writes_it_back_with_home_at_zero(tmp_path):
    src = tmp_path / "in.waypoints"
    src.write_text(MISSION)
    out = tmp_path / "out.waypoints"
    r = _sitl("--mission", str(src), "--mission-out", str(out), "--duration", "0.5",
              "--home", "47.0,8.0,400", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    back = waypoints.read(out)
    assert [it.command for it in back] == [16, 22, 16, 177, 21]
    assert (back[0].x, back[0].y) == (470000000, 80000000)  # home now, not the file's
    assert abs(back[0].z - 400) < 0.5
    assert [(it.x, it.y, it.z) for it in back[1:]] == \
        [(it.x, it.y, it.z) for it in waypoints.parse(MISSION)[1:]]


@pytest.mark.e2e
def test_cli_answers_a_bad_file_in_one_line(tmp_path):
    bad = tmp_path / "bad.waypoints"
    bad.write_text("QGC WPL 110\n0 1 0 16\n")
    r = _sitl("--mission", str(bad), "--duration", "0.5", cwd=tmp_path)
    assert r.returncode != 0
    line = r.stderr.strip().splitlines()[-1]
    assert f"--mission: {bad}:2: 4 fields" in line, r.stderr
    r = _sitl("--mission", str(tmp_path / "none.waypoints"), cwd=tmp_path)
    assert r.returncode != 0 and "none.waypoints: cannot read" in r.stderr
