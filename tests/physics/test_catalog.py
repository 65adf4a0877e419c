"""The 36-platform catalog against the paper's Table 1, and its physical consistency."""

import math

import numpy as np
import pytest

from ft_sitl import G
from ft_sitl.physics.catalog import catalog, load_platform_file, paper_values, to_toml
from ft_sitl.physics.synthesis import generate_virtual, synthesise


def test_names_and_order_match_table1(table1_rows):
    assert list(catalog()) == [r["name"] for r in table1_rows]
    cats = [p.category for p in catalog().values()]
    assert cats.count("real") == 18 and cats.count("virtual") == 18


def test_indicators_recomputed_from_physics_match_table1(table1_rows):
    cat = catalog()
    for r in table1_rows:
        p = cat[r["name"]]
        ind = p.indicators()
        assert p.mass_kg == float(r["mass_kg"])
        assert p.category == r["category"]
        # the table prints one decimal: recomputed values must round to the printed ones
        assert round(ind.twr_max, 1) == float(r["twr_max"]), p.name
        assert round(ind.alpha_xy_max_rad_s2, 1) == float(r["alpha_xy_max_rad_s2"]), p.name
        assert round(ind.alpha_z_max_rad_s2, 1) == float(r["alpha_z_max_rad_s2"]), p.name
        # indicators follow eq. 2 directly from c_T, w_max, m
        twr = 4 * p.thrust_coefficient * p.rotor_speed_max_rad_s**2 / (p.mass_kg * G)
        assert math.isclose(ind.twr_max, twr, rel_tol=1e-12)


def test_quad_x_torque_matches_paper_eq5():
    p = catalog()["1.50kg-DJI"]
    d, ct = p.arm_length_m, p.thrust_coefficient
    wmax2, wmin2 = p.rotor_speed_max_rad_s**2, p.rotor_speed_min_rad_s**2
    tau_x = d * ct * math.sqrt(2) / 2 * (2 * wmax2 - 2 * wmin2)
    tau_z = p.torque_thrust_ratio_m * ct * (2 * wmax2 - 2 * wmin2)
    assert np.allclose(p.max_torques(), [tau_x, tau_x, tau_z], rtol=1e-12)


def test_paper_means_of_real_and_virtual_sets():
    real = [p.indicators() for p in catalog().values() if p.category == "real"]
    virt = [p.indicators() for p in catalog().values() if p.category == "virtual"]
    for group, expect in ((real, (2.30, 99.92, 7.17)), (virt, (3.47, 824.20, 41.88))):
        means = (
            np.mean([i.twr_max for i in group]),
            np.mean([i.alpha_xy_max_rad_s2 for i in group]),
            np.mean([i.alpha_z_max_rad_s2 for i in group]),
        )
        # The paper's text quotes means of its unrounded data; the table's one-decimal TWR
        # values average to 2.317 for the real set against the quoted 2.30.
        assert means[0] == pytest.approx(expect[0], abs=0.02)
        assert means[1:] == pytest.approx(expect[1:], abs=0.01)


@pytest.mark.parametrize("name", list(catalog()))
def test_every_platform_is_physically_consistent(name):
    p = catalog()[name]
    jxx, jyy, jzz = p.inertia_kg_m2
    assert min(jxx, jyy, jzz) > 0
    assert jzz <= jxx + jyy and jxx <= jyy + jzz and jyy <= jxx + jzz
    assert 1.1 <= jzz / jxx <= 2.0
    # mass distribution: radius of gyration inside the rotor circle
    assert 0.05 <= jxx / (p.mass_kg * p.arm_length_m**2) <= 0.5
    # arm length plausible for the mass (250 mm .. 1 m wheelbase for 0.5-5.5 kg)
    assert 0.08 <= p.arm_length_m <= 0.5
    assert p.prop_diameter_m < math.sqrt(2) * p.arm_length_m  # props do not overlap
    tip_speed = p.rotor_speed_max_rad_s * p.prop_diameter_m / 2
    assert 60 <= tip_speed <= 260
    assert 0.005 <= p.motor_tau_up_s <= 0.1 and p.motor_tau_down_s >= p.motor_tau_up_s
    assert 0.03 <= p.torque_thrust_ratio_m / p.prop_diameter_m <= 0.15
    assert p.rotor_speed_min_rad_s < p.hover_rotor_speed_rad_s < p.rotor_speed_max_rad_s
    # the paper's narrowest gap (0.85 m) must be passable by every platform
    assert p.arm_length_m <= p.collision_radius_m < 0.425


def test_paper_values_are_kept_next_to_the_catalog(table1_rows):
    pv = paper_values()
    for r in table1_rows:
        assert pv[r["name"]]["paper_alpha_xy_max_rad_s2"] == float(r["alpha_xy_max_rad_s2"])


def test_catalog_round_trips_through_a_user_file(tmp_path):
    f = tmp_path / "cat.toml"
    f.write_text(to_toml(catalog().values()))
    loaded = load_platform_file(f)
    assert [p for p in loaded] == list(catalog().values())


def test_synthesise_rejects_an_impossible_design():
    # alpha_z far above what the roll agility allows needs Jzz > Jxx + Jyy
    with pytest.raises(ValueError, match="Jzz/Jxx"):
        synthesise("odd", 1.0, 3.0, 100.0, 90.0)
    with pytest.raises(ValueError, match="twr_max"):
        synthesise("heavy", 1.0, 0.9, 100.0, 10.0)


def test_generator_is_deterministic_and_stays_in_the_design_space():
    base = [p for p in catalog().values() if p.category == "virtual"]
    a = generate_virtual(12, 7, base)
    b = generate_virtual(12, 7, base)
    assert a == b
    assert generate_virtual(12, 8, base) != a
    lo = {k: min(getattr(p.indicators(), k) for p in base)
          for k in ("twr_max", "alpha_xy_max_rad_s2", "alpha_z_max_rad_s2")}
    hi = {k: max(getattr(p.indicators(), k) for p in base) for k in lo}
    names = set()
    for p in a:
        assert p.category == "virtual" and p.name not in names
        names.add(p.name)
        ind = p.indicators()
        for k in lo:
            assert lo[k] * 0.999 <= getattr(ind, k) <= hi[k] * 1.001
        assert min(q.mass_kg for q in base) <= p.mass_kg <= max(q.mass_kg for q in base)
        jxx, _, jzz = p.inertia_kg_m2
        assert jzz <= 2 * jxx
