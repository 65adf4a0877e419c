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
from ft_sitl.wire.convert import ned_to_world, to_offboard
from ft_sitl.wire.navigate import WireTask


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


def test_wire_task_round_trips_and_names_bad_fields():
    wt = WireTask(goal=[10.0, 5.0, 2.0], start=[0.0, 0.0, 2.0], start_yaw=0.3,
                  origin=[0.0, 0.0, 0.0])
    assert WireTask.from_json(wt.to_json()) == wt
    env = wt.env("udpin://0.0.0.0:14560", "mqtt://127.0.0.1:1883", "abc")
    assert env["FT_SITL_GOAL_NED"] == "5.000,10.000,-2.000"
    assert env["FT_SITL_MQTT"] == "mqtt://127.0.0.1:1883"
    assert json.loads(env["FT_SITL_TASK"])["goal"] == [10.0, 5.0, 2.0]
    with pytest.raises(ValueError, match="unknown field"):
        WireTask.from_json('{"goal": [1, 2, 3], "bogus": 1}')
    with pytest.raises(ValueError, match="task goal"):
        WireTask(goal=[1, 2], start=[0, 0, 1], start_yaw=0.0)
    with pytest.raises(ValueError, match="not JSON"):
        WireTask.from_json("{")


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
