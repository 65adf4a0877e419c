"""Wire trials served by the ArduCopter face (``--autopilot ardupilot``, issue 46): the
vehicle as ArduCopter on the wire, the navigator an ``ft-sitl navigate --lockstep`` MAVSDK
client that flies GUIDED; the rows equal the in-process rows but the wall times, as the
PX4 face's do."""

import json
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from ft_sitl import frames
from ft_sitl.mavlink.ardupilot.modes import GUIDED
from ft_sitl.mavlink.ardupilot.server import ArduPilotServer
from ft_sitl.mavlink.instances import InstanceLock
from ft_sitl.missions.campaign_file import CampaignError
from ft_sitl.missions.plan import plan_trial
from ft_sitl.missions.protocol import trial_vehicle
from ft_sitl.missions.spec import TrialSpecError
from ft_sitl.missions.trial import TrialSpec, run_trial
from ft_sitl.transport import faces, lockstep, transport
from ft_sitl.transport.mavlink_trial import run_trial_wire, worker_bus

pytestmark = pytest.mark.e2e  # (tests/lanes.py)

AGILE = "0.98kg-EGO Planner DIY"
FT_SITL = str(Path(sys.executable).parent / "ft-sitl")
#: the columns that measure wall time (and when the row was written)
WALL_COLUMNS = ("wall_time_s", "planner_time_s", "finished_utc")


def _differ(a: dict, b: dict) -> dict:
    return {k: (a[k], b.get(k)) for k in a
            if k not in WALL_COLUMNS and json.dumps(a[k]) != json.dumps(b.get(k))}


def test_a_lockstep_trial_over_the_arducopter_face_flies_guided_and_equals_in_process(
        tmp_path, monkeypatch):
    """The navigator's MAVSDK client switches the ArduCopter face to GUIDED (MAVSDK's
    offboard start on ArduPilot: DO_SET_MODE, custom mode 4) and streams its setpoints as
    SET_POSITION_TARGET_LOCAL_NED; at every navigator tick the vehicle reads as GUIDED on
    the wire and the flight controller flies the setpoint; the row is the in-process one."""
    spec = TrialSpec(algorithm="straight", platform=AGILE, family="forest", scenario_index=2)
    seen: dict = {"modes": set(), "set_mode": [], "targets": 0}
    on_message, tick = lockstep.LockstepPilot._on_message, lockstep.LockstepPilot.tick

    def watch_message(self, vehicle, m):  # what crossed the wire (then handled as ever)
        if m.get_type() == "COMMAND_LONG" and m.command == 176:  # MAV_CMD_DO_SET_MODE
            seen["set_mode"].append(int(m.param2))
        elif m.get_type() == "SET_POSITION_TARGET_LOCAL_NED":
            seen["targets"] += 1
        on_message(self, vehicle, m)

    def watch_tick(self, fleet, obs, m):
        tick(self, fleet, obs, m)
        agent = self.server.agents[0]
        seen["modes"].add((type(self.server).__name__, agent.vehicle.modes.number))

    monkeypatch.setattr(lockstep.LockstepPilot, "_on_message", watch_message)
    monkeypatch.setattr(lockstep.LockstepPilot, "tick", watch_tick)
    wire = lockstep.run_trial_lockstep(spec, autopilot="ardupilot", log_dir=tmp_path,
                                       **worker_bus(None)).row
    here = run_trial(spec).row
    assert not _differ(here, wire), _differ(here, wire)
    assert wire["reason"] == "collision" and wire["planner_calls"] > 10
    assert seen["modes"] == {("LockstepArduPilotServer", GUIDED)}
    assert seen["set_mode"] and set(seen["set_mode"]) == {GUIDED}
    assert seen["targets"] >= wire["planner_calls"]


def test_the_arducopter_face_keeps_the_trials_parameters():
    """The face writes ArduCopter's defaults into the flight controller (ANGLE_MAX 30
    degrees as MPC_TILTMAX_AIR, WPNAV_SPEED as MPC_XY_CRUISE, ...); a wire trial puts the
    trial's parameters back, so the vehicle flies as in-process."""
    spec = TrialSpec(algorithm="straight", platform=AGILE, family="forest", scenario_index=2)
    _, fleet = trial_vehicle(plan_trial(spec))
    trial = fleet.params[0].as_dict()
    with InstanceLock() as inst:
        plain = ArduPilotServer(fleet, frames.GeoReference(*frames.PX4_SITL_HOME),
                                base_instance=inst)
        changed = {k for k, v in fleet.params[0].as_dict().items() if trial[k] != v}
        assert {"MPC_TILTMAX_AIR", "MPC_XY_CRUISE"} <= changed  # (the test can fail)
        plain.close()
        _, fleet = trial_vehicle(plan_trial(spec))
        server, connect = faces.serve("ardupilot", fleet, inst, lockstep=True)
        try:
            assert fleet.params[0].as_dict() == trial
            assert connect == f"udpin://0.0.0.0:{faces.client_port(inst)}"
            assert isinstance(server, faces.LockstepArduPilotServer)
        finally:
            server.close()


def test_campaign_run_over_the_arducopter_face_records_it(tmp_path):
    """``ft-sitl campaign run --transport mavlink --autopilot ardupilot``: the row equals
    the in-process run's but the wall times (trial ids unchanged), and runs.json says which
    face flew it; --autopilot without --transport mavlink, or an unknown one, is a one-line
    error."""
    p = tmp_path / "c.toml"
    p.write_text(textwrap.dedent(f"""\
        name = "ap"
        trials = 1
        platforms = ["{AGILE}"]
        scenarios = [{{family = "narrow_gap", indices = [2]}}]
        algorithms = ["straight"]
        """))
    for out, extra in (("inproc", []), ("wire", ["--transport", "mavlink", "--autopilot",
                                                  "ardupilot"])):
        subprocess.run([FT_SITL, "campaign", "run", str(p), "--out", str(tmp_path / out),
                        "--quiet", "--no-report", *extra], check=True, capture_output=True)
    rows = {out: [json.loads(x) for x in (tmp_path / out / "trials.jsonl").read_text()
                  .splitlines()] for out in ("inproc", "wire")}
    assert len(rows["inproc"]) == len(rows["wire"]) == 1
    a, b = rows["inproc"][0], rows["wire"][0]
    assert a["trial_id"] == b["trial_id"] and not _differ(a, b), _differ(a, b)
    run = json.loads((tmp_path / "wire" / "runs.json").read_text())[-1]
    assert (run["transport"], run["lockstep"], run["autopilot"]) == ("mavlink", True,
                                                                      "ardupilot")
    assert "autopilot" not in json.loads((tmp_path / "inproc" / "runs.json").read_text())[-1]


def test_autopilot_options_refused_with_one_line(tmp_path):
    """--autopilot without --transport mavlink, the ArduCopter face free-running (not
    served yet: docs/wire.md) or an unknown face: one line naming the option."""
    p = tmp_path / "c.toml"
    p.write_text(f'name = "ap"\nplatforms = ["{AGILE}"]\nscenarios = ["forest"]\n'
                 'indices = [1]\nalgorithms = ["straight"]\n')
    for extra, line in (
            ([], "--autopilot ardupilot: only with --transport mavlink (in-process trials "
                 "have no MAVLink face)"),
            (["--transport", "mavlink", "--free-running"], faces.ARDUPILOT_LOCKSTEP_ONLY)):
        bad = subprocess.run([FT_SITL, "campaign", "run", str(p), "--out",
                              str(tmp_path / "x"), "--autopilot", "ardupilot", *extra],
                             capture_output=True, text=True)
        assert bad.returncode != 0 and bad.stderr.strip().splitlines() == [
            f"ft-sitl: error: {line}"], bad.stderr
    assert not (tmp_path / "x").exists()
    with pytest.raises(CampaignError, match=r"--autopilot: 'apm' is not one of px4, ardupilot"):
        transport("mavlink", autopilot="apm")
    spec = TrialSpec(algorithm="command", algorithm_params={"argv": ["true"]}, platform=AGILE,
                     family="forest", scenario_index=2)
    with pytest.raises(TrialSpecError, match="lockstep wire trials only"):
        run_trial_wire(spec, autopilot="ardupilot")
