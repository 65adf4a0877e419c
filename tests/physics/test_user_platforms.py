"""User platform files: both forms, both formats, and every kind of bad input."""

import pytest

from ft_sitl.physics.catalog import PlatformRegistry, catalog, load_platform_file
from ft_sitl.physics.platform import PlatformError

INDICATOR_TOML = """
[[platform]]
name = "my-racer"
layout = "quad_x"
mass_kg = 0.7
twr_max = 4.0
alpha_xy_max_rad_s2 = 600.0
alpha_z_max_rad_s2 = 30.0
"""

PHYSICAL_YAML = """
platform:
  name: my-plus
  layout: quad_plus
  mass_kg: 1.2
  arm_length_m: 0.2
  inertia_kg_m2: [0.012, 0.012, 0.021]
  prop_diameter_m: 0.23
  thrust_coefficient: 6.0e-6
  torque_thrust_ratio_m: 0.016
  rotor_speed_min_rad_s: 120
  rotor_speed_max_rad_s: 1100
  motor_tau_up_s: 0.02
  motor_tau_down_s: 0.025
  rotor_drag_coefficient: 1.0e-5
  body_drag_coefficient: [0.01, 0.01, 0.03]
  collision_radius_m: 0.27
"""


def write(tmp_path, name, text):
    f = tmp_path / name
    f.write_text(text)
    return f


def test_indicator_form_reproduces_the_indicators(tmp_path):
    (p,) = load_platform_file(write(tmp_path, "p.toml", INDICATOR_TOML))
    ind = p.indicators()
    assert p.category == "user"
    assert ind.twr_max == pytest.approx(4.0, rel=1e-12)
    assert ind.alpha_xy_max_rad_s2 == pytest.approx(600.0, rel=1e-12)
    assert ind.alpha_z_max_rad_s2 == pytest.approx(30.0, rel=1e-12)


def test_physical_form_in_yaml_with_plus_layout(tmp_path):
    (p,) = load_platform_file(write(tmp_path, "p.yaml", PHYSICAL_YAML))
    assert p.layout == "quad_plus" and p.inertia_kg_m2 == (0.012, 0.012, 0.021)
    # plus layout: only the two side rotors make roll torque (eq. 4)
    t_max, t_min = 6e-6 * 1100**2, 6e-6 * 120**2
    assert p.max_torques()[0] == pytest.approx(0.2 * (t_max - t_min))


def test_registry_adds_user_platforms_and_rejects_name_clashes(tmp_path):
    f = write(tmp_path, "p.toml", INDICATOR_TOML)
    reg = PlatformRegistry([f])
    assert reg.get("my-racer").mass_kg == 0.7
    assert len(reg.names()) == len(catalog()) + 1
    clash = write(tmp_path, "c.toml", INDICATOR_TOML.replace("my-racer", "0.60kg-EMAX"))
    with pytest.raises(PlatformError, match="0.60kg-EMAX.*already loaded"):
        PlatformRegistry([clash])


@pytest.mark.parametrize(
    "mutate, message",
    [
        (lambda t: t.replace("mass_kg = 0.7", "mass_kg = 0.7\nmass_g = 700"),
         r"unknown key\(s\) 'mass_g'"),
        (lambda t: t.replace("mass_kg = 0.7\n", ""), r"missing key\(s\) mass_kg"),
        (lambda t: t.replace("twr_max = 4.0", "twr_max = -4.0"), r"twr_max: -4.0 is outside"),
        (lambda t: t.replace("mass_kg = 0.7", 'mass_kg = "heavy"'),
         r"mass_kg: must be a number, got 'heavy'"),
        (lambda t: t.replace('layout = "quad_x"', 'layout = "hexa"'), r"layout.*'hexa'"),
        (lambda t: t.replace("mass_kg = 0.7", "mass_kg = nan"), r"mass_kg: nan is not a finite"),
        (lambda t: t.replace("twr_max = 4.0", "twr_max = 4.0\ntwr_mx = 1"),
         r"did you mean 'twr_max'"),
        (lambda t: t + t, r"name 'my-racer' appears twice"),
        (lambda t: t.replace("[[platform]]", "[[platfrom]]"),
         r"unknown key\(s\) 'platfrom' \(did you mean 'platform'\?\); allowed: platform"),
        (lambda t: t.replace(" = ", " == ", 1), r"not valid TOML"),
    ],
)
def test_bad_indicator_files_name_file_entry_and_key(tmp_path, mutate, message):
    f = write(tmp_path, "bad.toml", mutate(INDICATOR_TOML))
    with pytest.raises(PlatformError, match=message) as exc:
        load_platform_file(f)
    assert str(f) in str(exc.value)


@pytest.mark.parametrize(
    "old, new, message",
    [
        ("inertia_kg_m2: [0.012, 0.012, 0.021]", "inertia_kg_m2: [0.012, 0.012, 0.03]",
         "triangle inequality Jzz <= Jxx \\+ Jyy"),
        ("inertia_kg_m2: [0.012, 0.012, 0.021]", "inertia_kg_m2: [0.012, 0.012]",
         "needs a list of 3"),
        ("rotor_speed_max_rad_s: 1100", "rotor_speed_max_rad_s: 700",
         "TWR_max 0.9.*1.05"),
        ("rotor_speed_min_rad_s: 120", "rotor_speed_min_rad_s: 1200",
         "must be below rotor_speed_max"),
        ("arm_length_m: 0.2", "arm_length_m: 200", "arm_length_m: 200.0 m is outside"),
        ("collision_radius_m: 0.27", "collision_radius_m: 0.1", "smaller than the arm length"),
        ("motor_tau_up_s: 0.02", "motor_tau_up_s: 0", "motor_tau_up_s: 0.0 s is outside"),
    ],
)
def test_bad_physical_files(tmp_path, old, new, message):
    assert old in PHYSICAL_YAML
    f = write(tmp_path, "bad.yaml", PHYSICAL_YAML.replace(old, new))
    with pytest.raises(PlatformError, match=message) as exc:
        load_platform_file(f)
    assert "my-plus" in str(exc.value) and str(f) in str(exc.value)


def test_unreadable_and_unknown_files(tmp_path):
    with pytest.raises(PlatformError, match="missing.toml: no such platform file"):
        load_platform_file(tmp_path / "missing.toml")
    with pytest.raises(PlatformError,
                       match=r"p\.json: unknown platform file type \.json; use \.toml, \.yaml"):
        load_platform_file(write(tmp_path, "p.json", "{}"))
    with pytest.raises(PlatformError, match=r"not valid YAML \(line 1, column \d+\)"):
        load_platform_file(write(tmp_path, "p.yaml", "platform: [unclosed"))
    with pytest.raises(PlatformError, match="top level must be a table"):
        load_platform_file(write(tmp_path, "p.yaml", "- 1\n- 2\n"))
