"""Trials with a geofence (TrialSpec.fence, the campaign's ``fence`` axis): the flight
controller keeps it as PX4 does; a breach it takes the vehicle over on ends the trial as
``geofence``, one it only warns about is counted; rows carry the fence and the breaches and
rerun bit for bit; bad fences are refused naming the field.

The yard (conftest): start (5, 2, 1.5), goal (5, 18, 1.5), a wall across y = 10. The
straight navigator flies north along x = 5 and leaves the box y < 6 about 1.6 s into the
navigation."""

import dataclasses
import json
import math

import pytest

from ft_sitl.autopilot import commander as cm
from ft_sitl.cli.missions import differences
from ft_sitl.missions.campaign import run_campaign
from ft_sitl.missions.campaign_file import CampaignError, load_campaign
from ft_sitl.missions.report import REASON_COLOURS
from ft_sitl.missions.results import REASONS, to_frame
from ft_sitl.missions.spec import TrialSpec, TrialSpecError
from ft_sitl.missions.trial import run_trial
from ft_sitl.navigation.base import Limits
from tests.missions.conftest import PLATFORM, campaign_file, read_jsonl, run_exe

#: the yard's southern part: the start is inside, the goal and the wall outside
BOX = [[0, 0], [10, 0], [10, 6], [0, 6]]


def fenced(yard, fence) -> TrialSpec:
    return TrialSpec("straight", PLATFORM, "yard", scenario_file=str(yard), fence=fence,
                     limits=Limits(timeout_s=6.0))


def fly(spec):
    """The row, and the commander's (main mode, sub mode, terminated) after every advance
    of the navigation."""
    modes = []
    row = run_trial(spec, monitor=lambda fleet, t_us: modes.append(
        (fleet.commanders[0].main_mode, fleet.commanders[0].sub_mode,
         fleet.commanders[0].terminated))).row
    return row, modes


@pytest.mark.parametrize("action, mode", [
    ("land", (cm.MAIN_AUTO, cm.SUB_LAND, False)),
    ("hold", (cm.MAIN_AUTO, cm.SUB_LOITER, False)),
    (3, (cm.MAIN_AUTO, cm.SUB_RTL, False)),  # return, by GF_ACTION's number
    ("terminate", None),  # (motors off: whatever the mode)
])
def test_leaving_an_inclusion_fence_takes_gf_action_and_ends_the_trial(yard, action, mode):
    row, modes = fly(fenced(yard, {"action": action,
                                   "polygons": [{"inclusion": True, "vertices": BOX}]}))
    name = {3: "return"}.get(action, action)
    assert (row["reason"], row["success"]) == ("geofence", False)
    assert row["detail"] == f"breached: outside the fence (GF_ACTION {name})"
    assert modes[0][0] == cm.MAIN_OFFBOARD  # the navigator flew ...
    if action == "terminate":
        assert modes[-1][2]
    else:
        assert modes[-1] == mode  # ... until the flight controller took over
    # one breach, where the straight line crosses y = 6 (start y = 2 at 4 m/s, accelerating)
    assert row["fence_breaches"] == 1
    assert 1.0 < row["fence_breach_s"] <= row["nav_time_s"] < row["fence_breach_s"] + 0.05
    assert json.loads(row["fence"]) == {
        "action": name, "max_hor_dist_m": 0.0, "max_ver_dist_m": 0.0, "circles": [],
        "polygons": [{"inclusion": True, "vertices": [[0.0, 0.0], [10.0, 0.0], [10.0, 6.0],
                                                       [0.0, 6.0]]}]}


def test_a_warning_breach_is_counted_and_the_flight_goes_on(yard):
    plain, _ = fly(fenced(yard, None))
    row, modes = fly(fenced(yard, {"action": "warning",
                                   "polygons": [{"inclusion": True, "vertices": BOX}]}))
    # the straight line meets the wall, fence or not; the fence only counted the breach
    assert plain["reason"] == row["reason"] == "collision"
    assert row["path_length_m"] == plain["path_length_m"]
    assert {m[0] for m in modes} == {cm.MAIN_OFFBOARD}
    assert (row["fence_breaches"], plain["fence_breaches"]) == (1, 0)
    assert 1.0 < row["fence_breach_s"] < row["nav_time_s"] and math.isnan(
        plain["fence_breach_s"])
    assert plain["fence"] == "" and "fence" not in fenced(yard, None).to_dict()


def test_an_exclusion_circle_and_a_height_limit_breach_as_px4_says(yard):
    # an exclusion circle on the line ahead: the breach is entering it
    row, _ = fly(fenced(yard, {"action": "hold", "circles": [
        {"inclusion": False, "center": [5, 8], "radius_m": 1.0}]}))
    assert (row["reason"], row["detail"]) == ("geofence",
                                              "breached: outside the fence (GF_ACTION hold)")
    # no higher than 1 m above home: the take-off to the 1.5 m start breaches it
    row, _ = fly(fenced(yard, {"action": "land", "max_ver_dist_m": 1.0}))
    assert (row["reason"], row["detail"]) == (
        "geofence", "breached: more than 1 m above home (GF_ACTION land) before navigation "
                    "started")
    assert (row["nav_time_s"], row["fence_breaches"]) == (0.0, 0)


def test_from_protocol_8_a_fence_breached_on_the_ground_refuses_arming_as_px4(yard):
    keep_out = {"action": "hold", "circles": [  # around the take-off point
        {"inclusion": False, "center": [5, 2], "radius_m": 1.0}]}
    spec = fenced(yard, keep_out)
    assert spec.protocol >= 8
    row, _ = fly(spec)
    assert (row["reason"], row["detail"]) == (
        "geofence", "arming refused: Preflight Fail: Geofence violation")
    assert (row["nav_time_s"], row["fence_breaches"]) == (0.0, 0)
    assert row["sim_time_s"] == 0.0  # nothing flew
    # protocol 7 armed, and the breach acted in the air, as every older row says
    row7, _ = fly(dataclasses.replace(spec, protocol=7))
    assert (row7["reason"], row7["detail"]) == (
        "geofence", "breached: outside the fence (GF_ACTION hold) before navigation started")
    assert row7["sim_time_s"] > 0.0


FENCED = """\
name = "fenced"
algorithms = ["straight"]
platforms = ["1.00kg-SunnySky"]
scenarios = [{file = "yard.yaml"}]
trials = 1
fence = [
  {},
  {action = "land", polygons = [{inclusion = true, vertices = [[0, 0], [10, 0], [10, 6], [0, 6]]}]},
]
[limits]
timeout_s = 6.0
"""


@pytest.mark.e2e
def test_a_fence_axis_gives_rows_that_carry_the_fence_and_rerun_bit_for_bit(yard, tmp_path,
                                                                           cli_env):
    c = load_campaign(campaign_file(yard.parent, "fenced.toml", FENCED))
    specs = c.trial_specs()
    assert [s.fence is None for s in specs] == [True, False]
    assert len({s.seed for s in specs}) == 1  # the axis compares like with like
    assert c.spec_dict()["fence"][0] == {}
    summary = run_campaign(c, tmp_path / "out", progress=False)
    assert (summary.ran, summary.errors) == (2, [])
    rows = {r["fence"]: r for r in read_jsonl(tmp_path / "out" / "trials.jsonl")}
    assert rows[""]["reason"] == "collision"
    fenced_row = next(r for k, r in rows.items() if k)
    assert (fenced_row["reason"], fenced_row["fence_breaches"]) == ("geofence", 1)
    table = to_frame(rows.values())
    assert sorted(table["reason"].astype(str)) == ["collision", "geofence"]
    assert list(table["fence_breaches"]) == [0, 1] or list(table["fence_breaches"]) == [1, 0]
    # the spec in the row rebuilds the trial: the same row again, the same id
    spec = TrialSpec.from_dict(json.loads(fenced_row["spec"]))
    assert spec.trial_id == fenced_row["trial_id"] and spec.fence == specs[1].fence
    assert differences(run_trial(spec).row, fenced_row) == []
    proc = run_exe("trial", "rerun", tmp_path / "out", fenced_row["trial_id"][:8],
                   env=cli_env)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "geofence - breached: outside the fence (GF_ACTION land)" in proc.stdout
    assert "identical to the stored result" in proc.stdout
    proc = run_exe("campaign", "check", campaign_file(yard.parent, "fenced.toml", FENCED),
                   env=cli_env)
    assert "x 2 fences" in proc.stdout and \
        "  fence:      none; land: 1 inclusion polygon" in proc.stdout


BOWTIE = [[0, 0], [10, 10], [10, 0], [0, 10]]


@pytest.mark.parametrize("fence, message", [
    ({"action": "explode", "max_hor_dist_m": 5},
     r"^fence: action: must be a GF_ACTION, by name or number: 'none' \(0\), 'warning' \(1\), "
     r"'hold' \(2\), 'return' \(3\), 'terminate' \(4\), 'land' \(5\); got 'explode'$"),
    ({"action": 6, "max_hor_dist_m": 5}, r"^fence: action: .* got 6$"),
    ({"polygons": [{"inclusion": True, "vertices": BOWTIE}]},
     r"^fence\.polygons\[0\]: the polygon's edges 0-1 and 2-3 cross \(a self-intersecting "
     r"polygon\)$"),
    ({"polygons": [{"inclusion": True, "vertices": [[0, 0], [math.nan, 0], [5, 5]]}]},
     r"^fence\.polygons\[0\]: a polygon vertex is not a finite position$"),
    ({"polygons": [{"inclusion": True, "vertices": [[0, 0], [5, 5]]}]},
     r"^fence\.polygons\[0\]: a polygon needs at least 3 vertices, got 2$"),
    ({"polygons": [{"inclusion": True, "vertices": [[0, 0, 0], [5, 5, 0], [5, 0, 0]]}]},
     r"^fence\.polygons\[0\]: the polygon's vertices must be \[x, y\] pairs"),
    ({"polygons": [{"inclusion": "yes", "vertices": BOX}]},
     r"^fence\.polygons\[0\]: inclusion: must be true \(keep inside\) or false"),
    ({"polygons": [{"vertices": BOX}]}, r"^fence\.polygons\[0\]: missing key\(s\) inclusion$"),
    ({"circles": [{"inclusion": False, "center": [1, 2], "radius": 3}]},
     r"^fence\.circles\[0\]: unknown key\(s\) 'radius' \(did you mean 'radius_m'\?\)"),
    ({"circles": [{"inclusion": False, "center": [1, math.inf], "radius_m": 3}]},
     r"^fence\.circles\[0\]: the circle's centre is not a finite position$"),
    ({"circles": [{"inclusion": False, "center": [1, 2], "radius_m": 0}]},
     r"^fence\.circles\[0\]: the circle's radius must be a positive number of metres"),
    ({"circles": [{"inclusion": False, "center": [k, 0], "radius_m": 0.1}
                  for k in range(257)]},
     r"^fence: 257 items, more than the 256 fence or rally items a vehicle stores$"),
    ({"max_ver_dist_m": math.nan}, r"^fence: max_ver_dist_m: GF_MAX_VER_DIST: nan is not "
                                   r"finite$"),
    ({"polygon": []}, r"^fence: unknown key\(s\) 'polygon' \(did you mean 'polygons'\?\)"),
    ({"action": "land"}, r"^fence: fences nothing \(no polygon, no circle, no maximum "
                         r"distance\)"),
    ("land", r"^fence: must be a table of fence settings"),
])
def test_bad_fences_are_refused_naming_the_field(fence, message):
    with pytest.raises(TrialSpecError, match=message):
        TrialSpec("straight", PLATFORM, "maze", fence=fence)


def test_a_trial_sets_gf_parameters_through_its_fence_only():
    with pytest.raises(TrialSpecError, match=r"^params: GF_ACTION is set by the trial "
                                             r"protocol: use fence\.action instead$"):
        TrialSpec("straight", PLATFORM, "maze", params={"GF_ACTION": 5})
    # the canonical fence: the action by name, numbers as floats, every key
    spec = TrialSpec("straight", PLATFORM, "maze", fence={"action": 5, "max_hor_dist_m": 30})
    assert spec.fence == {"action": "land", "max_hor_dist_m": 30.0, "max_ver_dist_m": 0.0,
                          "polygons": [], "circles": []}
    assert TrialSpec.from_dict(json.loads(spec.to_json())) == spec
    assert TrialSpec("straight", PLATFORM, "maze", fence={}).fence is None


@pytest.mark.parametrize("axis, message", [
    ('fence = [{}, {polygons = [{inclusion = true, vertices = [[0, 0], [10, 10], [10, 0], '
     '[0, 10]]}]}]',
     r"bad\.toml: fence\[1\]\.polygons\[0\]: the polygon's edges 0-1 and 2-3 cross"),
    ('fence = {action = "explode", max_hor_dist_m = 5}',
     r"bad\.toml: fence: action: must be a GF_ACTION"),
    ('fence = [{max_hor_dist_m = 5}, {max_hor_dist_m = 5.0}]',
     r"bad\.toml: fence\[1\]: the same fence settings twice"),
    ('fence = "land"', r"bad\.toml: fence: must be a table of fence settings or a non-empty "
                       r"list of them"),
    ('params = {GF_MAX_HOR_DIST = 5}',
     r"bad\.toml: params: GF_MAX_HOR_DIST is set by the trial protocol: use "
     r"fence\.max_hor_dist_m instead"),
])
def test_bad_fence_axes_are_named_by_file_and_entry(yard, axis, message):
    text = FENCED.split("fence = [")[0] + axis + "\n"
    with pytest.raises(CampaignError, match=message):
        load_campaign(campaign_file(yard.parent, "bad.toml", text))


def test_every_exit_reason_has_a_report_colour():
    assert set(REASON_COLOURS) == set(REASONS)
