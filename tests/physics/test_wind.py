"""Wind in the plant (ft_sitl.physics.wind): Dryden turbulence has the standard's variance
and spectrum on a long seeded run; a hovering vehicle in steady wind tilts into it by the
angle the drag model predicts (differently for a light and a heavy platform); a 1-cosine
gust peaks halfway; the noise is a pure function of (seed, step); bad settings are named."""

import math

import numpy as np
import pytest
from scipy.optimize import fsolve
from scipy.signal import welch

from ft_sitl import G
from ft_sitl.physics.catalog import catalog
from ft_sitl.physics.noise import gauss
from ft_sitl.physics.wind import INTENSITY_W20_M_S, Wind, dryden_scales, wind_series
from ft_sitl.schema import SchemaError
from ft_sitl.sim.lockstep import Simulation

DT = 0.01  # the discretisation is exact at any step; 10 ms keeps the long run short


def _components(wind: Wind, seconds: float, seed: int = 7):
    """Turbulence only (mean removed), as (u along the wind, v across it, w up)."""
    n = int(seconds / DT)
    s = wind_series(wind.row(DT, seed), n, DT) - wind.mean()
    to = math.radians(wind.values["from_deg"] + 180.0)
    ux, uy = math.sin(to), math.cos(to)
    return s[:, 0] * ux + s[:, 1] * uy, -s[:, 0] * uy + s[:, 1] * ux, s[:, 2]


def _phi(kind: str, sigma: float, T: float, w: np.ndarray) -> np.ndarray:
    """Dryden's one-sided spectra in rad/s (each integrates to sigma^2 over 0..inf)."""
    x = T * w
    if kind == "u":
        return sigma**2 * (2 * T / math.pi) / (1 + x**2)
    return sigma**2 * (T / math.pi) * (1 + 3 * x**2) / (1 + x**2) ** 2


def test_dryden_scales_are_mil_f_8785c_low_altitude():
    s = dryden_scales(50 * 0.3048, 30 * 0.514444)  # 50 ft, moderate (W20 = 30 kt)
    k = 0.177 + 0.000823 * 50
    assert s["L_w"] == pytest.approx(50 * 0.3048)
    assert s["L_u"] == s["L_v"] == pytest.approx(50 / k**1.2 * 0.3048)
    assert s["sigma_w"] == pytest.approx(0.1 * 30 * 0.514444)
    assert s["sigma_u"] == pytest.approx(s["sigma_w"] / k**0.4)
    # below 10 ft the formulas are evaluated at 10 ft
    assert dryden_scales(0.5, 10.0) == dryden_scales(10 * 0.3048, 10.0)
    assert INTENSITY_W20_M_S["severe"] == pytest.approx(45 * 0.514444)


def test_turbulence_variance_and_spectrum_match_the_dryden_model():
    wind = Wind({"speed_m_s": 6.0, "from_deg": 225.0, "turbulence": "light",
                 "turbulence_altitude_m": 5.0})
    s = wind.sigmas()
    V = wind.passing_speed()
    u, v, w = _components(wind, 4000.0)
    for name, series, sigma, L in (("u", u, s["sigma_u"], s["L_u"]),
                                   ("v", v, s["sigma_v"], s["L_v"]),
                                   ("w", w, s["sigma_w"], s["L_w"])):
        T = L / V
        # the variance: 4000 s holds >= 4000 / (2 T) independent stretches (T <= 5 s here)
        assert np.var(series) == pytest.approx(sigma**2, rel=0.15), name
        assert abs(np.mean(series)) < 0.1 * sigma, name
        f, p = welch(series, fs=1 / DT, nperseg=8192)
        # one-sided PSD per Hz -> per rad/s: P(f) = 2 pi Phi(2 pi f)
        model = 2 * math.pi * _phi("u" if name == "u" else "vw", sigma, T, 2 * math.pi * f)
        for lo, hi in ((0.02, 0.1), (0.1, 0.5), (0.5, 2.0), (2.0, 5.0)):
            band = (f >= lo) & (f < hi)
            ratio = p[band].mean() / model[band].mean()
            assert ratio == pytest.approx(1.0, abs=0.2), (name, lo, hi, ratio)


def test_at_a_1_khz_physics_rate_the_held_turbulence_keeps_its_variance():
    wind = Wind({"speed_m_s": 5.0, "turbulence": "moderate"})
    s = wind_series(wind.row(0.001, 2), 1_500_000, 0.001) - wind.mean()
    # sampled every 10 ms, held between: each value ten times
    assert np.array_equal(s[0:10], np.repeat(s[0:1], 10, axis=0))
    assert not np.array_equal(s[9], s[10])
    assert np.var(s[:, 2]) == pytest.approx(wind.sigmas()["sigma_w"] ** 2, rel=0.15)


def test_the_noise_is_a_pure_function_of_seed_step_and_component():
    a = [gauss(5, k, j) for k in (0, 1, 1000) for j in range(5)]
    assert a == [gauss(5, k, j) for k in (0, 1, 1000) for j in range(5)]
    assert a != [gauss(6, k, j) for k in (0, 1, 1000) for j in range(5)]
    draws = np.array([gauss(11, k, 0) for k in range(50_000)])
    assert abs(draws.mean()) < 0.02 and draws.std() == pytest.approx(1.0, abs=0.02)
    # a run split into two calls equals one call
    wind = Wind({"speed_m_s": 4.0, "turbulence": "moderate"})
    whole = wind_series(wind.row(DT, 3), 2000, DT)
    row = wind.row(DT, 3)
    split = np.vstack([wind_series(row, 700, DT, 0), wind_series(row, 1300, DT, 700)])
    assert np.array_equal(whole, split)


def _predicted_pitch(p, wind_m_s: float) -> float:
    """Pitch (rad) at which thrust, rotor drag and body drag balance gravity for a vehicle
    at rest in a steady horizontal wind along +x (the plant's force model, solved)."""
    m, n, ct = p.mass_kg, p.n_rotors, p.thrust_coefficient
    krd = p.rotor_drag_coefficient
    bdx, _, bdz = p.body_drag_coefficient

    def residual(z):
        theta, thrust = z
        w = math.sqrt(thrust / (n * ct))
        # air velocity relative to the body, world (-W, 0, 0), into a body pitched theta
        vbx, vbz = -wind_m_s * math.cos(theta), -wind_m_s * math.sin(theta)
        fbx = -krd * n * w * vbx - bdx * abs(vbx) * vbx
        fbz = thrust - bdz * abs(vbz) * vbz
        fx = math.cos(theta) * fbx + math.sin(theta) * fbz
        fz = -math.sin(theta) * fbx + math.cos(theta) * fbz
        return [fx, fz - m * G]

    theta, _ = fsolve(residual, [0.0, p.mass_kg * G], xtol=1e-13)
    return float(theta)


def test_a_hovering_vehicle_tilts_into_steady_wind_by_the_drag_models_angle():
    cat = catalog()
    light, heavy = cat["0.98kg-EGO Planner DIY"], cat["4.50kg-T-MOTOR"]
    sim = Simulation([light, heavy])
    tilts = []
    for i in range(2):
        sim.start_hovering(i, [0.0, 10.0 * i, 2.0])
        sim.set_wind(i, {"speed_m_s": 8.0, "from_deg": 270.0})  # blowing east (+x)
    sim.run(30.0)  # (the position loop's integrator brings it back slowly)
    for i, p in enumerate((light, heavy)):
        assert np.linalg.norm(sim.velocity(i)) < 1e-3  # at rest: the forces balance
        roll, pitch, yaw = sim.euler(i)
        want = _predicted_pitch(p, 8.0)
        assert abs(want) > math.radians(1.0)
        # a positive pitch about y tips thrust towards +x: into this wind it is negative
        assert pitch == pytest.approx(want, abs=math.radians(0.005)), (p.name,)
        assert abs(roll) < 1e-6
        tilts.append(abs(pitch))
    assert tilts[0] != pytest.approx(tilts[1], rel=0.05)  # the same wind, felt differently
    assert np.allclose(sim.wind_velocity(0), [8.0, 0.0, 0.0], atol=1e-12)


def test_a_one_cosine_gust_peaks_halfway_and_ends():
    wind = Wind({"gust_m_s": 6.0, "gust_from_deg": 180.0, "gust_vertical_m_s": 1.0,
                 "gust_start_s": 1.0, "gust_duration_s": 2.0})
    s = wind_series(wind.row(DT, 0), 500, DT)
    t = np.arange(500) * DT
    assert np.allclose(s[t < 1.0 - 1e-9], 0.0)
    peak = np.argmin(np.abs(t - 2.0))
    assert s[peak] == pytest.approx([0.0, 6.0, 1.0], abs=1e-9)  # from the south: north
    quarter = np.argmin(np.abs(t - 1.5))
    assert s[quarter, 1] == pytest.approx(3.0, abs=1e-9)
    assert np.allclose(s[t > 3.0 + 1e-9], 0.0)


def test_calm_air_is_the_default_and_changes_nothing():
    assert Wind().calm and not Wind().row(0.001, 0).any()
    a = Simulation(catalog()["1.00kg-SunnySky"])
    b = Simulation(catalog()["1.00kg-SunnySky"])
    for sim in (a, b):
        sim.start_hovering(0, [0.0, 0.0, 2.0])
    b.set_wind(0, {"speed_m_s": 0.0})
    a.run(2.0)
    b.run(2.0)
    assert np.array_equal(a.x, b.x)


@pytest.mark.parametrize("values,message", [
    ({"speed_m_s": -3.0}, "speed_m_s: must be a number 0..40 (m/s), got -3.0"),
    ({"speed": 3.0}, "has no parameter 'speed'; did you mean 'speed_m_s'?"),
    ({"turbulence": "strong"}, "turbulence"),
    ({"gust_duration_s": 0.0}, "gust_duration_s"),
    ({"from_deg": 400.0}, "from_deg"),
])
def test_bad_wind_settings_are_named(values, message):
    with pytest.raises(SchemaError, match="^wind") as exc:
        Wind(values)
    assert message in str(exc.value)
