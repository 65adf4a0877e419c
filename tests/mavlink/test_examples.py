"""The example scripts fly the SITL exactly as written (run as separate processes).

Host-speed independent: the MAVSDK scripts are served client-paced (the simulated clock
never runs more than the span past their last message, the speed factor its ceiling), so
a script starved of CPU sees a slower world, not a different one. The offboard scripts'
span, 0.5 s, is half the offboard-loss timeout (COM_OF_LOSS_T, 1 s): MAVSDK streams the
setpoint at 20 Hz, so a starved script can never lose offboard control. The mission script
sends only MAVSDK's heartbeat (1 Hz) while the mission flies; its span is one heartbeat
period at the speed factor, so the clock waits only when the script falls silent for
longer. The pymavlink script sends nothing between its commands, so client pacing would
stop the world while it waits for telemetry: it runs wall-paced, and nothing it checks
depends on the host's speed (it waits for the altitude up to 30 s, then lands either
way, and waits for the disarm without limit)."""

import subprocess
import sys
from pathlib import Path

import pytest

from .sitl_harness import running_sitl

pytestmark = pytest.mark.e2e  # (tests/lanes.py)

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
#: the offboard scripts' pacing span: half of COM_OF_LOSS_T's default (s)
OFFBOARD_SPAN_S = 0.5
#: MAVSDK's heartbeat period (wall s)
HEARTBEAT_S = 1.0


@pytest.mark.parametrize("script, speed, span, expect", [
    ("mavsdk_offboard.py", 6.0, OFFBOARD_SPAN_S, "-- landed and disarmed"),
    ("mavsdk_mission.py", 8.0, 8.0 * HEARTBEAT_S, "-- landed and disarmed"),
    ("pymavlink_takeoff_land.py", 2.0, None, "-- landed and disarmed"),
    ("mavsdk_square_check.py", 6.0, OFFBOARD_SPAN_S, "SQUARE OK"),
])
def test_example_flies(script, speed, span, expect):
    pacing = {} if span is None else {"pace": "client", "pace_span_s": span}
    with running_sitl(speed_factor=speed, params=None, **pacing) as server:
        proc = subprocess.run([sys.executable, str(EXAMPLES / script)], capture_output=True,
                              text=True, timeout=600)
        assert proc.returncode == 0, proc.stdout + proc.stderr
        assert expect in proc.stdout
        assert not server.fleet.commanders[0].armed
        assert server.fleet.sim.max_impact_speed(0) < 1.5
        # the offboard scripts never lost offboard control on the way
        assert not any("offboard" in t.lower() and "lost" in t.lower()
                       for _, t in server.fleet.commanders[0].statustexts), \
            server.fleet.commanders[0].statustexts
        if span is not None:
            assert server.pace == "client" and server.pace_span_s == span
