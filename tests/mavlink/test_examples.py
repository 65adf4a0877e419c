"""The example scripts fly the SITL exactly as written (run as separate processes)."""

import subprocess
import sys
from pathlib import Path

import pytest

from .sitl_harness import running_sitl

pytestmark = pytest.mark.e2e  # (tests/lanes.py)

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


@pytest.mark.parametrize("script, speed, expect", [
    ("mavsdk_offboard.py", 6.0, "-- landed and disarmed"),
    ("mavsdk_mission.py", 8.0, "-- landed and disarmed"),
    ("pymavlink_takeoff_land.py", 2.0, "-- landed and disarmed"),
    ("mavsdk_square_check.py", 6.0, "SQUARE OK"),
])
def test_example_flies(script, speed, expect):
    with running_sitl(speed_factor=speed, params=None) as server:
        proc = subprocess.run([sys.executable, str(EXAMPLES / script)], capture_output=True,
                              text=True, timeout=240)
        assert proc.returncode == 0, proc.stdout + proc.stderr
        assert expect in proc.stdout
        assert not server.fleet.commanders[0].armed
        assert server.fleet.sim.max_impact_speed(0) < 1.5
