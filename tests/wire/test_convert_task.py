"""Pure pieces of the wire path: setpoint conversion to MAVSDK, the task a navigator process
is given, campaign entries naming a user's command."""

import json
import math
import textwrap

import numpy as np
import pytest

from ft_sitl.autopilot.setpoints import Setpoint
from ft_sitl.missions.campaign import Transport
from ft_sitl.missions.campaign_file import CampaignError, load_campaign
from ft_sitl.missions.plan import plan_trial
from ft_sitl.missions.spec import TrialSpec
from ft_sitl.navigation.base import Task, TaskError
from ft_sitl.wire.convert import ned_to_world, to_offboard
from ft_sitl.wire.navigate import task_env, task_from_json


def test_trajectory_setpoint_becomes_local_ned_with_nan_kept():
    sp = Setpoint.trajectory(position=[11.0, 22.0, 3.0], velocity=[1.0, 2.0, math.nan],
                             acceleration=[0.0, 0.5, 0.0], yaw=0.0)
    cmd = to_offboard(sp, origin_enu=[10.0, 20.0, 0.0])
    assert cmd.kind == "pva"
    assert cmd.position == pytest.approx((2.0, 1.0, -3.0))  # N = y, E = x, D = -z
    assert cmd.velocity[:2] == pytest.approx((2.0, 1.0)) and math.isnan(cmd.velocity[2])
    assert cmd.acceleration == pytest.approx((0.5, 0.0, -0.0))
    assert cmd.yaw_deg == pytest.approx(90.0)  # ENU yaw 0 = east = NED heading 90
    velocity_only = to_offboard(Setpoint.trajectory(position=[math.nan, math.nan, 2.0],
                                                    velocity=[1.0, 0.0, math.nan]), [0, 0, 0])
    assert math.isnan(velocity_only.position[0]) and velocity_only.position[2] == -2.0
    assert math.isnan(velocity_only.yaw_deg)
    np.testing.assert_allclose(ned_to_world([2.0, 1.0, -3.0], [10.0, 20.0, 0.0]),
                               [11.0, 22.0, 3.0])


def test_attitude_and_rates_convert_and_motor_states_are_refused():
    level_east = Setpoint.attitude([1.0, 0.0, 0.0, 0.0], thrust=0.5)  # ENU yaw 0
    cmd = to_offboard(level_east, [0, 0, 0])
    assert cmd.kind == "attitude" and cmd.thrust == 0.5
    assert cmd.euler_deg == pytest.approx((0.0, 0.0, 90.0), abs=1e-9)
    rates = to_offboard(Setpoint.body_rates([0.1, 0.2, 0.3], thrust=0.4), [0, 0, 0])
    assert rates.rates_deg_s == pytest.approx(tuple(np.degrees([0.1, -0.2, -0.3])))
    with pytest.raises(ValueError, match="cannot be sent as an offboard setpoint"):
        to_offboard(Setpoint.off(), [0, 0, 0])


def test_the_task_travels_as_a_document_and_names_bad_fields():
    task = Task.from_dict({"goal": [10.0, 5.0, 2.0], "start": [0.0, 0.0, 2.0],
                           "start_yaw": 0.3})
    back = task_from_json(json.dumps(task.to_dict()))
    assert back.to_dict() == task.to_dict()
    assert back.rng.random() == task.rng.random()
    env = task_env(task, "udpin://0.0.0.0:14560", "mqtt://127.0.0.1:1883", "abc")
    assert env["FT_SITL_GOAL_NED"] == "5.000,10.000,-2.000"
    assert env["FT_SITL_MQTT"] == "mqtt://127.0.0.1:1883"
    assert json.loads(env["FT_SITL_TASK"])["goal"] == [10.0, 5.0, 2.0]
    with pytest.raises(TaskError, match="unknown field"):
        task_from_json('{"goal": [1, 2, 3], "bogus": 1}')
    with pytest.raises(TaskError, match="task goal"):
        Task.from_dict({"goal": [1, 2], "start": [0, 0, 1], "start_yaw": 0.0})
    with pytest.raises(TaskError, match="missing field.*start_yaw"):
        Task.from_dict({"goal": [1, 2, 3], "start": [0, 0, 1]})
    with pytest.raises(TaskError, match="task seed"):
        Task.from_dict({"goal": [1, 2, 3], "start": [0, 0, 1], "start_yaw": 0.0,
                        "seed": [-1]})
    with pytest.raises(TaskError,
                       match=r"limits: timeout_s: must be a number 0.1..3600 \(s\), got 0"):
        Task.from_dict({"goal": [1, 2, 3], "start": [0, 0, 1], "start_yaw": 0.0,
                        "timeout_s": 0})
    with pytest.raises(TaskError, match="not JSON"):
        task_from_json("{")


def test_the_wire_task_is_the_plans_in_process_task_from_protocol_9():
    """One plan, one task: the navigator over MAVLink is told what the in-process one is,
    its random stream included (protocol 9). Up to 8 the wire seeded its stream from one
    integer drawn from the same entropy, and its camera noise from seed + 1000 trial:
    those rows keep flying so."""
    spec = TrialSpec("pgo", "0.98kg-EGO Planner DIY", "forest", seed=3, trial=2)
    plan = plan_trial(spec)
    here, there = plan.task(), task_from_json(json.dumps(plan.task(wire=True).to_dict()))
    assert here.to_dict() == there.to_dict()
    assert here.rng.random(4).tolist() == there.rng.random(4).tolist()
    np.testing.assert_array_equal(there.origin, plan.scenario.takeoff)
    assert there.observe_approach and there.map_fusion_hz == 20.0
    assert there.footprint_m == plan.footprint_m > 0

    old = plan_trial(TrialSpec("pgo", "0.98kg-EGO Planner DIY", "forest", seed=3, trial=2,
                               protocol=8))
    wire = old.task(wire=True)
    legacy = np.random.default_rng(int(np.random.SeedSequence([3, 2]).generate_state(1)[0]))
    assert wire.rng.random(4).tolist() == legacy.random(4).tolist()
    assert old.task().rng.random(4).tolist() == plan.task().rng.random(4).tolist()
    camera = np.random.default_rng(np.random.SeedSequence([3 + 1000 * 2, 7]))
    assert old.wire_streams.rng("camera").random(3).tolist() == camera.random(3).tolist()
    assert plan.wire_streams.rng("camera").random(3).tolist() == \
        plan.streams.rng("camera").random(3).tolist()


def _campaign(tmp_path, algorithms: str):
    p = tmp_path / "c.toml"
    p.write_text(textwrap.dedent(f"""\
        trials = 1
        platforms = ["0.98kg-EGO Planner DIY"]
        scenarios = ["forest"]
        indices = [1]
        {algorithms}
        """))
    return load_campaign(p)


def test_campaign_command_entries(tmp_path):
    c = _campaign(tmp_path, 'algorithms = ["straight", {label = "mine", '
                            'command = "python nav.py --fast"}]')
    entry = c.algorithms[1]
    assert (entry.name, entry.label, entry.params) == ("command", "mine",
                                                       {"argv": ["python", "nav.py", "--fast"]})
    spec = [s for s in c.trial_specs() if s.algorithm == "command"][0]
    assert spec.algorithm_params == {"argv": ["python", "nav.py", "--fast"]}
    with pytest.raises(CampaignError, match="needs a 'label'"):
        _campaign(tmp_path, 'algorithms = [{command = "python nav.py"}]')
    with pytest.raises(CampaignError, match="takes only 'label' and 'command'"):
        _campaign(tmp_path, 'algorithms = [{name = "ego", label = "x", command = "a"}]')
    with pytest.raises(CampaignError, match="command: is empty"):
        _campaign(tmp_path, 'algorithms = [{label = "x", command = ""}]')
    with pytest.raises(CampaignError, match="command: No closing quotation"):
        _campaign(tmp_path, '''algorithms = [{label = "x", command = "python 'nav.py"}]''')
    with pytest.raises(CampaignError, match="--transport"):
        Transport("carrier-pigeon")
    with pytest.raises(CampaignError, match="--speed-factor"):
        Transport("mavlink", 0.0)
