"""The navigators' declared parameters: defaults, validation, display."""

import math
from pathlib import Path

import pytest

from ft_sitl.navigation.registry import NavigatorError, create, describe, get_class, parameters

CAMERA = {"camera": "benchmark", "camera_width": None, "camera_height": None,
          "camera_rate_hz": None}

# what the constructors' signatures gave before the parameters were declared (captured at
# 5da4228): a changed default changes how a planner flies
DEFAULTS = {
    "straight": {"speed_m_s": None},
    # (EGO's replanning rule and emergency time: the original's from protocol 11, which
    # protocols 1-10 pin back to "single" and 0.8 s through missions.plan.navigator_params)
    "ego": {"max_acc_m_s2": 3.0, "planning_horizon_m": 7.5, "replan_threshold_m": 1.5,
            "no_replan_threshold_m": 2.0, "emergency_time_s": 1.0, "latency_s": 0.01,
            "measured_latency": False, **CAMERA, "replan_rule": "original"},
    "fast": {"max_acc_m_s2": 2.0, "planning_horizon_m": 7.0, "replan_threshold_m": 1.5,
             "no_replan_threshold_m": 2.0, "emergency_time_s": 0.8, "latency_s": 0.02,
             "measured_latency": False, **CAMERA},
    "pgo": {"max_acc_m_s2": 2.0, "local_segment_m": 7.0, "replan_period_s": 0.5,
            "no_replan_threshold_m": 2.0, "stop_distance_m": 0.5, "ctrl_pt_dist_m": 0.3,
            "latency_s": 0.03, "measured_latency": False, **CAMERA},
    "navrl": {"checkpoint": None, "action_limit_m_s": 1.0, "latency_s": 0.01,
              "measured_latency": False, "use_shield": True,
              "shield_cluster_radius_m": math.sqrt(0.2), "dynamic_obstacles": "tracked",
              **CAMERA},
}


@pytest.mark.parametrize("name", list(DEFAULTS))
def test_defaults_are_the_old_signatures(name):
    got = parameters(get_class(name))
    assert list(got.items()) == list(DEFAULTS[name].items())
    assert all(type(v) is type(DEFAULTS[name][k]) for k, v in got.items())


@pytest.mark.parametrize("name", ["straight", "ego", "fast", "pgo"])
def test_a_created_navigator_holds_the_resolved_defaults(name):
    assert create(name).settings == DEFAULTS[name]


def test_planner_attributes_come_from_the_settings():
    nav = create("pgo", {"replan_period_s": 0.25, "camera_rate_hz": 10})
    assert nav.replan_period == 0.25 and nav.camera.rate_hz == 10.0
    assert nav.max_acc == 2.0 and nav.latency == 0.03 and nav.segment_len == 7.0


@pytest.mark.parametrize("name,params,message", [
    ("ego", {"planing_horizon_m": 5.0},
     "navigator 'ego' has no parameter 'planing_horizon_m'; did you mean "
     "'planning_horizon_m'? (parameters: max_acc_m_s2, planning_horizon_m,"),
    ("ego", {"planning_horizon_m": 50.0},
     "navigator 'ego': planning_horizon_m: must be a number 2..20 (m), got 50.0"),
    ("fast", {"measured_latency": "yes"},
     "navigator 'fast': measured_latency: must be true or false, got 'yes'"),
    ("pgo", {"camera": "kinect"},
     "navigator 'pgo': camera: must be 'benchmark' or 'd435', got 'kinect'"),
    ("ego", {"camera_width": 320.5},
     "navigator 'ego': camera_width: must be an integer 16..1280, or none (px), got 320.5"),
    ("straight", {"speed_m_s": 0},
     "navigator 'straight': speed_m_s: must be a number 0.1..50, or none (m/s), got 0"),
])
def test_invalid_parameters_are_refused_by_name(name, params, message):
    with pytest.raises(NavigatorError) as exc:
        create(name, params)
    assert str(exc.value).startswith(message)


@pytest.mark.parametrize("name", list(DEFAULTS))
def test_describe_lists_every_parameter_with_unit_and_range(name):
    rows = describe(name).rows()
    assert [r["name"] for r in rows] == list(DEFAULTS[name])
    for r in rows:
        assert r["unit"] and r["range"] and r["doc"], r
    by_name = {r["name"]: r for r in rows}
    if "latency_s" in by_name:
        assert by_name["latency_s"]["unit"] == "s"
        assert by_name["latency_s"]["range"] == "a number 0..1"


def test_describe_refuses_an_unknown_navigator():
    with pytest.raises(NavigatorError, match="unknown navigator 'eg0'; did you mean 'ego'"):
        describe("eg0")


def test_the_documented_tables_are_the_declarations():
    text = (Path(__file__).resolve().parents[2] / "docs" / "planners.md").read_text()
    for name in DEFAULTS:
        block = (f"<!-- BEGIN generated: describe({name!r}).markdown() -->\n"
                 f"{describe(name).markdown()}\n<!-- END generated -->")
        assert block in text, f"docs/planners.md: regenerate the table of {name!r}"
