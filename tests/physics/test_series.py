"""The controlled platform series (ft_sitl.physics.series): one catalog body, one indicator
changed at a time, everything else identical; loaded, listed and flown like any platform."""

import math

import numpy as np
import pytest

from ft_sitl.autopilot import cascade
from ft_sitl.autopilot.gains import build_gains
from ft_sitl.autopilot.params import ParamSet
from ft_sitl.missions.trial import TrialSpec, run_trial
from ft_sitl.physics.body import world_points
from ft_sitl.physics.catalog import (
    PlatformRegistry,
    catalog,
    load_platform_file,
    series,
    to_toml,
)
from ft_sitl.physics.platform import PlatformError
from ft_sitl.physics.series import (
    SERIES_BASES,
    SERIES_CATEGORY,
    TWR_LEVELS,
    alpha_xy_range,
    gamma,
    twr_range,
    with_alpha_xy,
    with_twr,
)
from ft_sitl.physics.synthesis import GAMMA_MAX

# The shipped names: campaign files and stored rows name them, so a change here changes
# what those rows mean (docs/platforms.md, "Controlled platform series").
NAMES = {
    "0.55kg-UAV 1": ("twr1.2", "twr1.5", "twr2.0", "twr3.0", "twr4.0", "twr6.0",
                     "axy232", "axy368", "axy583", "axy925", "axy1467"),
    "1.00kg-SunnySky": ("twr1.2", "twr1.5", "twr2.0", "twr3.0", "twr4.0", "twr6.0",
                        "axy228", "axy363", "axy578", "axy921", "axy1467"),
    "5.00kg-UAV 16": ("twr1.2", "twr1.5", "twr2.0", "twr3.0", "twr4.0", "twr6.0",
                      "axy94", "axy187", "axy371", "axy738", "axy1467"),
}
# what only the body, mass and geometry decide: identical to the base in every member
BODY_KEYS = ("layout", "mass_kg", "arm_length_m", "prop_diameter_m", "thrust_coefficient",
             "torque_thrust_ratio_m", "motor_tau_up_s", "motor_tau_down_s",
             "rotor_drag_coefficient", "body_drag_coefficient", "collision_radius_m",
             "body_size_m", "rotor_disk_thickness_m", "rotor_height_m")
REL = 0.01  # the acceptance: indicators as requested within 1 %


def members():
    """(base, kind, requested value, member) for every shipped member."""
    cat, ser = catalog(), series()
    out = []
    for base_name, suffixes in NAMES.items():
        base = cat[base_name]
        for s in suffixes:
            kind, value = ("twr", float(s[3:])) if s.startswith("twr") else \
                ("axy", float(s[3:]))
            out.append((base, kind, value, ser[f"series-{base_name.replace(' ', '')}-{s}"]))
    return out


def ind(p):
    i = p.indicators()
    return i.twr_max, i.alpha_xy_max_rad_s2, i.alpha_z_max_rad_s2


def test_the_shipped_series_names_category_and_order():
    assert SERIES_BASES == tuple(NAMES)
    want = [f"series-{b.replace(' ', '')}-{s}" for b, ss in NAMES.items() for s in ss]
    assert list(series()) == want
    assert {p.category for p in series().values()} == {SERIES_CATEGORY} == {"series"}
    assert all(p.name not in catalog() for p in series().values())


def test_every_member_has_its_base_body_mass_and_geometry():
    for base, _, _, p in members():
        for key in BODY_KEYS:
            assert getattr(p, key) == getattr(base, key), (p.name, key)
        assert p.body() == base.body(), p.name
        assert p.body().describe() == base.body().describe()
        # the collision body's parts, posed: the arrays the guard and plots use
        q = np.array([math.cos(0.3), 0.0, math.sin(0.3) * 0.6, math.sin(0.3) * 0.8])
        np.testing.assert_array_equal(world_points(p.body(), [1.0, -2.0, 3.0], q),
                                      world_points(base.body(), [1.0, -2.0, 3.0], q))
        assert p.hover_rotor_speed_rad_s == pytest.approx(base.hover_rotor_speed_rad_s,
                                                          rel=1e-12)


def test_twr_members_have_the_requested_twr_and_their_base_alphas():
    seen = set()
    for base, kind, value, p in members():
        if kind != "twr":
            continue
        twr, axy, az = ind(p)
        b_twr, b_axy, b_az = ind(base)
        assert twr == pytest.approx(value, rel=REL), p.name
        assert axy == pytest.approx(b_axy, rel=REL) and az == pytest.approx(b_az, rel=REL)
        # exactly, in fact: the motors and the inertia scale together
        assert (twr, axy, az) == pytest.approx((value, b_axy, b_az), rel=1e-12)
        # stronger motors spin the same propeller faster; the idle ratio stays
        assert p.rotor_speed_max_rad_s > base.rotor_speed_max_rad_s or value <= b_twr
        assert p.rotor_speed_min_rad_s / p.rotor_speed_max_rad_s == pytest.approx(
            base.rotor_speed_min_rad_s / base.rotor_speed_max_rad_s, rel=1e-12)
        seen.add((base.name, value))
    assert len(seen) == 3 * len(TWR_LEVELS)
    assert {v for _, v in seen} == set(TWR_LEVELS) and min(TWR_LEVELS) == 1.2 \
        and max(TWR_LEVELS) == 6.0


def test_alpha_members_have_the_requested_alpha_and_their_base_twr():
    cat_alphas = [ind(p)[1] for p in catalog().values()]
    by_base: dict[str, list[float]] = {}
    for base, kind, value, p in members():
        if kind != "axy":
            continue
        twr, axy, az = ind(p)
        b_twr, b_axy, b_az = ind(base)
        assert axy == pytest.approx(value, rel=REL), p.name
        assert twr == pytest.approx(b_twr, rel=REL), p.name
        assert (axy, twr) == pytest.approx((value, b_twr), rel=1e-12)  # exactly, in fact
        # alpha_z moves with alpha_xy: J_zz / J_xx is held (docs/platforms.md)
        assert az / axy == pytest.approx(b_az / b_axy, rel=REL), p.name
        assert p.rotor_speed_max_rad_s == base.rotor_speed_max_rad_s
        by_base.setdefault(base.name, []).append(axy)
    for name, alphas in by_base.items():
        lo = alpha_xy_range(catalog()[name])[0]
        # from the catalog's (or the body's) lowest to the catalog's highest, log-spaced
        assert alphas[0] == pytest.approx(math.ceil(max(min(cat_alphas), lo)), rel=1e-12)
        assert alphas[-1] == pytest.approx(math.floor(max(cat_alphas)), rel=1e-12)
        steps = np.diff(np.log(alphas))
        assert steps.max() / steps.min() < 1.02, name
    # the large body reaches the low end of the catalog's range best
    assert by_base["5.00kg-UAV 16"][0] < 100 < by_base["1.00kg-SunnySky"][0]


def test_no_member_needs_more_inertia_than_a_frame_can_have():
    for _, _, _, p in members():
        assert gamma(p) <= GAMMA_MAX * (1 + 1e-9), p.name
    # the middle body's TWR-6 member sits on the ceiling: its own catalog platform
    assert gamma(series()["series-1.00kg-SunnySky-twr6.0"]) == pytest.approx(GAMMA_MAX)


def test_members_load_from_a_platform_file_exactly_as_built(tmp_path):
    f = tmp_path / "series.toml"
    f.write_text(to_toml(series().values()))
    loaded = load_platform_file(f)
    assert loaded == list(series().values())


def test_registry_lists_and_finds_the_series_but_all_means_the_catalog(tmp_path):
    reg = PlatformRegistry()
    assert [p.name for p in reg.all()] == list(catalog())
    assert reg.names() == list(catalog())
    every = reg.all(with_series=True)
    assert [p.name for p in every] == list(catalog()) + list(series())
    assert [p.name for p in reg.category("series")] == list(series())
    assert len(reg.category("real")) == 18
    assert reg.get("series-5.00kg-UAV16-twr1.2") == series()["series-5.00kg-UAV16-twr1.2"]
    with pytest.raises(PlatformError, match="did you mean .*'series-5.00kg-UAV16-twr1.2'"):
        reg.get("series-5.00kg-UAV16-twr1.3")
    clash = tmp_path / "c.toml"
    clash.write_text(to_toml([series()["series-0.55kg-UAV1-twr2.0"]]))
    with pytest.raises(PlatformError, match="series-0.55kg-UAV1-twr2.0.*already loaded"):
        PlatformRegistry([clash])


@pytest.mark.parametrize("mode", ["bandwidth", "px4"])
def test_the_controller_builds_gains_for_every_member(mode):
    params = ParamSet({"FT_GAIN_MODE": {"bandwidth": 0, "px4": 1}[mode]})
    for _, _, _, p in members():
        g = build_gains(p, params, 0.001)
        scale = g[cascade.G_TSCALE:cascade.G_TSCALE + 3]
        want = p.inertia_kg_m2 if mode == "bandwidth" else p.max_torques()
        np.testing.assert_allclose(scale, want, rtol=1e-12)
        assert g[cascade.G_FMAX] == pytest.approx(p.thrust_max_n)


@pytest.mark.parametrize("base_name, key, call, value, allowed", [
    ("0.55kg-UAV 1", "twr_max", with_twr, 9.0, "[1.05, 8]"),
    ("5.45kg-JFRC", "twr_max", with_twr, 6.0, "[1.05, 2.95023]"),
    ("0.55kg-UAV 1", "twr_max", with_twr, 1.0, "[1.05, 8]"),
    ("5.00kg-UAV 16", "alpha_xy_max_rad_s2", with_alpha_xy, 55.6, "[93.0792, 20000] rad/s^2"),
    ("0.55kg-UAV 1", "alpha_xy_max_rad_s2", with_alpha_xy, 30000.0,
     "[231.489, 20000] rad/s^2"),
])
def test_a_request_the_body_cannot_carry_is_refused_with_the_range(base_name, key, call,
                                                                   value, allowed):
    base = catalog()[base_name]
    with pytest.raises(PlatformError) as exc:
        call(base, value)
    msg = str(exc.value)
    assert "\n" not in msg and base_name in msg and f"{key}: {value:g}" in msg
    assert f"outside the allowed range {allowed} for this body (" in msg
    # the reason given is the violated end's
    assert ("inertia" in msg) == (base_name == "5.45kg-JFRC" or key.startswith("alpha")
                                  and value < 100)


def test_the_ranges_are_where_the_inertia_reaches_the_ceiling():
    jfrc = catalog()["5.45kg-JFRC"]
    hi = twr_range(jfrc)[1]
    assert gamma(with_twr(jfrc, hi)) == pytest.approx(GAMMA_MAX, rel=1e-9)
    lo = alpha_xy_range(jfrc)[0]
    assert gamma(with_alpha_xy(jfrc, lo)) == pytest.approx(GAMMA_MAX, rel=1e-9)
    with pytest.raises(PlatformError, match="is not a finite number"):
        with_twr(jfrc, float("nan"))


@pytest.mark.slow
def test_the_weakest_and_strongest_twr_members_fly_the_straight_baseline():
    """Forest 1 on the straight baseline: both fly the base's line at cruise speed into the
    tree on it (the baseline does not avoid); the weak one saturates its motors on the way,
    the strong one never."""
    def fly(name):
        spec = TrialSpec(algorithm="straight", platform=name, family="forest",
                         scenario_index=1)
        return run_trial(spec).row

    base = fly("5.00kg-UAV 16")
    weak, strong = fly("series-5.00kg-UAV16-twr1.2"), fly("series-5.00kg-UAV16-twr6.0")
    for row in (weak, strong):
        assert row["platform_category"] == "series"
        assert row["reason"] == base["reason"] and row["detail"] == base["detail"]
        assert row["path_length_m"] == pytest.approx(base["path_length_m"], abs=0.1)
        assert row["mean_speed_m_s"] > 3.5
    assert weak["twr_max"] == pytest.approx(1.2) and strong["twr_max"] == pytest.approx(6.0)
    assert weak["saturation_fraction"] > 0.01 and strong["saturation_fraction"] == 0.0
