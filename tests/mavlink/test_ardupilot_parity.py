"""scripts/ardupilot_parity.py: the committed side-by-side run (docs/ardupilot-parity/,
a real ArduCopter 4.7-dev SITL and the face) reads back as its committed table, and the
session itself runs through against the face."""

import importlib.util
import json
from pathlib import Path

import pytest

from .ardupilot_harness import free_ardupilot_sitl

ROOT = Path(__file__).resolve().parents[2]
RUN = ROOT / "docs" / "ardupilot-parity"
_spec = importlib.util.spec_from_file_location("ardupilot_parity",
                                               ROOT / "scripts" / "ardupilot_parity.py")
parity = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(parity)


def _load(name):
    return json.loads((RUN / name).read_text())


def test_the_committed_table_is_the_comparison_of_the_committed_observations():
    real, ours = _load("arducopter.json"), _load("ft-sitl.json")
    assert parity.compare(real, ours) == (RUN / "parity.md").read_text()
    rows = {name: (a, b, same) for name, a, b, same in parity.rows(real, ours)}
    # what both answered alike: SET_MODE is not acknowledged, nothing streams by default
    assert rows["SET_MODE message GUIDED"][2] == "same"
    assert real["set_mode_message_guided"]["ack"] is None
    assert rows["streams, default SRn_* (Hz)"][0] == "HEARTBEAT 1.2"
    # and what differed: ArduCopter boots in STABILIZE
    assert real["heartbeat"]["custom_mode"] == 0
    assert rows["HEARTBEAT"][2] == "differs"


def test_compare_marks_a_changed_answer_and_nothing_else():
    ours = _load("ft-sitl.json")
    other = json.loads(json.dumps(ours))
    other["label"] = "changed"
    other["mode_unknown_99"]["texts"] = ["No such mode"]  # (the old wording)
    changed = [name for name, _, _, same in parity.rows(ours, other) if same == "differs"]
    assert changed == ["SET_MODE 99"]


def test_run_names_a_missing_binary_in_one_line(tmp_path, capsys):
    with pytest.raises(SystemExit):
        parity.main(["run", "--arducopter", str(tmp_path / "nope"), "--defaults",
                     str(tmp_path / "x.parm"), "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert err.endswith(f"--arducopter: {tmp_path / 'nope'}: no such file")


@pytest.mark.e2e  # (tests/lanes.py: a SITL and a TCP client)
def test_the_session_runs_through_against_the_face():
    """The whole session, every step, against the face at four times real time (the
    suite's time): what is checked, its answers and the flight's outcome, does not depend
    on the speed (the script measures rates and heights over the vehicle's own clock)."""
    with free_ardupilot_sitl(speed_factor=4.0) as (_server, k):
        obs = parity.observe(f"tcp:127.0.0.1:{parity.tcp_ports(k)[0]}", "ft-sitl")
    assert (obs["heartbeat"]["type"], obs["heartbeat"]["autopilot"]) == (2, 3)
    assert set(obs["streams_default"]["hz"]) == {"HEARTBEAT"}
    assert obs["mission_upload"]["ack"] == "MAV_MISSION_ACCEPTED"
    items = obs["mission_download"]["items"]
    assert [it["command"] for it in items] == [16, 22, 16, 20]
    assert items[2]["x"] == round(parity.HOME[0] * 1e7) + 900
    f = obs["flight"]
    assert f["takeoff_ack"] == "ACCEPTED" and f["takeoff"]["reached_4.75m"]
    assert f["goto"]["reached_0.5m"]
    assert f["land"]["disarmed"]
