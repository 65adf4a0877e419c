"""MAVProxy (the real program) connects on the GCS port, lists parameters, sets one and
switches modes, as it does with PX4 SITL.

MAVProxy 1.8.75's ``mode NAME`` passes PX4's (base, main, sub) tuple into a float field
and fails before sending anything, against any PX4 vehicle; its ``long DO_SET_MODE`` is
what works with PX4, so that is what the test types.
"""

import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

from ft_sitl.autopilot.params import PARAMS

from .sitl_harness import running_sitl

pytestmark = pytest.mark.e2e  # (tests/lanes.py)

MAVPROXY = shutil.which("mavproxy.py", path=str(Path(sys.executable).parent))


def test_mavproxy_lists_params_sets_one_and_switches_modes(tmp_path):
    assert MAVPROXY, "mavproxy is a test dependency (scripts/setup.sh --test installs it)"
    with running_sitl() as server:
        proc = subprocess.Popen(
            [sys.executable, MAVPROXY, "--master=udpin:127.0.0.1:14550", "--source-system=250",
             "--nowait", f"--state-basedir={tmp_path}"],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
            cwd=tmp_path)
        cmd = server.fleet.commanders[0]
        try:
            deadline = time.time() + 60
            out = []
            while time.time() < deadline:
                line = proc.stdout.readline()
                out.append(line)
                if f"Received {len(PARAMS)} parameters" in line:
                    break
            assert any(f"Received {len(PARAMS)} parameters" in s for s in out), "".join(out)
            proc.stdin.write("param set MPC_XY_VEL_MAX 3.5\nlong DO_SET_MODE 1 4 3\n")
            proc.stdin.flush()
            deadline = time.time() + 15
            while time.time() < deadline and (cmd.mode_name != "AUTO.LOITER" or
                                              server.fleet.params[0]["MPC_XY_VEL_MAX"] != 3.5):
                time.sleep(0.2)
            assert server.fleet.params[0]["MPC_XY_VEL_MAX"] == 3.5
            assert cmd.mode_name == "AUTO.LOITER"
            proc.stdin.write("long DO_SET_MODE 1 3 0\n")
            proc.stdin.flush()
            deadline = time.time() + 10
            while time.time() < deadline and cmd.mode_name != "POSCTL":
                time.sleep(0.2)
            assert cmd.mode_name == "POSCTL"
            saved = (tmp_path / "mav.parm").read_text() if (tmp_path / "mav.parm").exists() \
                else ""
            assert "MIS_TAKEOFF_ALT" in saved
        finally:
            proc.stdin.write("exit\n")
            proc.stdin.close()
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                proc.kill()
