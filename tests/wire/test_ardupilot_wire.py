"""Wire trials served by the ArduCopter face (``--autopilot ardupilot``, issue 46): the
vehicle as ArduCopter on the wire, the navigator an ``ft-sitl navigate`` MAVSDK client that
flies GUIDED; in lockstep the rows equal the in-process rows but the wall times, as the
PX4 face's do; free-running the client asks for its telemetry's rates first (ArduPilot
streams nothing until asked) and a user's command navigator flies too."""

import json
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from pymavlink.dialects.v20 import ardupilotmega as apm

from ft_sitl import frames
from ft_sitl.mavlink.ardupilot.modes import GUIDED
from ft_sitl.mavlink.ardupilot.server import ArduPilotServer
from ft_sitl.mavlink.instances import InstanceLock
from ft_sitl.missions.campaign_file import CampaignError
from ft_sitl.missions.plan import plan_trial
from ft_sitl.missions.protocol import trial_vehicle
from ft_sitl.missions.trial import TrialSpec, run_trial
from ft_sitl.transport import faces, lockstep, transport, wire_trial
from ft_sitl.transport.mavlink_trial import run_trial_wire, worker_bus
from ft_sitl.wire.navigate import ARDUPILOT_RATES_HZ

pytestmark = pytest.mark.e2e  # (tests/lanes.py)

AGILE = "0.98kg-EGO Planner DIY"
FT_SITL = str(Path(sys.executable).parent / "ft-sitl")
REPO = Path(__file__).resolve().parents[2]
#: MAV_CMD_DO_SET_MODE, MAV_CMD_SET_MESSAGE_INTERVAL
DO_SET_MODE, SET_MESSAGE_INTERVAL = 176, 511
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
    """--autopilot without --transport mavlink, or an unknown face: one line naming the
    option."""
    p = tmp_path / "c.toml"
    p.write_text(f'name = "ap"\nplatforms = ["{AGILE}"]\nscenarios = ["forest"]\n'
                 'indices = [1]\nalgorithms = ["straight"]\n')
    bad = subprocess.run([FT_SITL, "campaign", "run", str(p), "--out", str(tmp_path / "x"),
                          "--autopilot", "ardupilot"], capture_output=True, text=True)
    assert bad.returncode != 0 and bad.stderr.strip().splitlines() == [
        "ft-sitl: error: --autopilot ardupilot: only with --transport mavlink (in-process "
        "trials have no MAVLink face)"], bad.stderr
    assert not (tmp_path / "x").exists()
    with pytest.raises(CampaignError, match=r"--autopilot: 'apm' is not one of px4, ardupilot"):
        transport("mavlink", autopilot="apm")
    spec = TrialSpec(algorithm="straight", platform=AGILE, family="forest", scenario_index=2)
    with pytest.raises(ValueError, match=r"--autopilot: 'apm' is not one of px4, ardupilot"):
        run_trial_wire(spec, autopilot="apm")


def _watch_the_wire(monkeypatch) -> dict:
    """What the client sends a free-running trial's ArduCopter face: the modes it asks
    for, the messages whose rates it asks for, and the vehicle's mode at each setpoint."""
    seen: dict = {"servers": [], "set_mode": [], "intervals": set(), "modes": set()}
    serve = wire_trial.serve

    def watching(*args, **kwargs):
        server, connect = serve(*args, **kwargs)
        seen["servers"].append(type(server).__name__)

        def on_message(vehicle, m):
            if m.get_type() == "COMMAND_LONG" and m.command == DO_SET_MODE:
                seen["set_mode"].append(int(m.param2))
            elif m.get_type() == "COMMAND_LONG" and m.command == SET_MESSAGE_INTERVAL:
                seen["intervals"].add(int(m.param1))
            elif m.get_type() == "SET_POSITION_TARGET_LOCAL_NED":
                seen["modes"].add(server.agents[vehicle].vehicle.modes.number)

        server.on_message = on_message
        return server, connect

    monkeypatch.setattr(wire_trial, "serve", watching)
    return seen


def test_a_free_running_trial_over_the_arducopter_face_reaches_the_goal(tmp_path,
                                                                       monkeypatch):
    """The baseline on an easy Narrow-Gap configuration (its gap straight ahead: in-process
    a success), free-running over the ArduCopter face: the client asks for its telemetry
    (SET_MESSAGE_INTERVAL: SYS_STATUS for the health, HOME_POSITION, the positions and
    attitude), arms, takes off and flies GUIDED (every setpoint arrives in GUIDED); it
    reaches the goal as in-process, the same path to within a few per cent (simulated
    times: the wire's latency, not the wall clock)."""
    seen = _watch_the_wire(monkeypatch)
    spec = TrialSpec(algorithm="straight", platform=AGILE, family="narrow_gap",
                     scenario_index=1)
    row = run_trial_wire(spec, speed_factor=2.0, autopilot="ardupilot", log_dir=tmp_path,
                         **worker_bus(None)).row
    here = run_trial(spec).row
    assert here["reason"] == "success"  # (the configuration is the easy one)
    assert row["reason"] == "success", row["detail"]
    assert row["path_length_m"] == pytest.approx(here["path_length_m"], rel=0.05)
    assert row["nav_time_s"] == pytest.approx(here["nav_time_s"], rel=0.2)
    assert seen["servers"] == ["FreeRunningArduPilotServer"]
    assert set(seen["set_mode"]) == {GUIDED} and seen["modes"] == {GUIDED}
    asked = {apm.MAVLINK_MSG_ID_SYS_STATUS, apm.MAVLINK_MSG_ID_HOME_POSITION,
             apm.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, apm.MAVLINK_MSG_ID_LOCAL_POSITION_NED,
             apm.MAVLINK_MSG_ID_ATTITUDE}
    assert asked <= seen["intervals"], seen["intervals"]
    assert {"health", "home", "position_velocity_ned"} <= set(ARDUPILOT_RATES_HZ)


def test_a_users_command_navigator_flies_the_arducopter_face(tmp_path, monkeypatch):
    """A ``command`` navigator (examples/user_navigator.py: MAVSDK, asks for the rates on
    ArduPilot) is served client-paced by the ArduCopter face and judged as on PX4's."""
    seen = _watch_the_wire(monkeypatch)
    spec = TrialSpec(algorithm="command", platform=AGILE, family="forest", scenario_index=2,
                     algorithm_params={"argv": [sys.executable,
                                                str(REPO / "examples" / "user_navigator.py")]},
                     label="user")
    row = run_trial_wire(spec, speed_factor=3.0, pace_span_s=0.5, autopilot="ardupilot",
                         log_dir=tmp_path, **worker_bus(None)).row
    # the example climbs 0.5 m and flies the straight line: it navigated and was judged
    assert row["nav_time_s"] > 1.0 and row["reason"] != "navigator_error", row["detail"]
    assert row["path_length_m"] > 3.0
    assert seen["servers"] == ["FreeRunningArduPilotServer"] and seen["modes"] == {GUIDED}


def test_campaign_run_free_running_over_the_arducopter_face(tmp_path):
    """``campaign run --transport mavlink --autopilot ardupilot --free-running``: the trial
    flies (the easy configuration: a success, as in-process) and runs.json records the
    face and that it ran free."""
    p = tmp_path / "c.toml"
    p.write_text(textwrap.dedent(f"""\
        name = "ap-free"
        trials = 1
        platforms = ["{AGILE}"]
        scenarios = [{{family = "narrow_gap", indices = [1]}}]
        algorithms = ["straight"]
        """))
    subprocess.run([FT_SITL, "campaign", "run", str(p), "--out", str(tmp_path / "w"),
                    "--quiet", "--no-report", "--transport", "mavlink", "--autopilot",
                    "ardupilot", "--free-running"], check=True, capture_output=True)
    rows = [json.loads(x) for x in (tmp_path / "w" / "trials.jsonl").read_text()
            .splitlines()]
    assert [r["reason"] for r in rows] == ["success"], rows[0]["detail"]
    run = json.loads((tmp_path / "w" / "runs.json").read_text())[-1]
    assert (run["transport"], run["lockstep"], run["autopilot"]) == ("mavlink", False,
                                                                      "ardupilot")
