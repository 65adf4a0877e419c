"""Sensor models for autopilot in the loop: what an autopilot's drivers read on our vehicle.

A real autopilot does not see our true state; it sees an IMU, a magnetometer, a
barometer and a GPS receiver. :class:`SensorSuite` turns the truth of a
:class:`~ft_sitl.bridge.vehicle.BridgeVehicle` (NED position relative to the spawn point,
NED velocity, attitude ``q_ned_frd``, body rates and specific force in FRD) into those
readings, in the units the wire carries (PX4's HIL_SENSOR / HIL_GPS):

- **IMU**: accelerometer = specific force (body FRD, m/s^2; at rest level it reads
  (0, 0, -g)), gyroscope = body rates (FRD, rad/s). White noise from a noise density
  (std = density * sqrt(sample rate)) plus a slowly drifting bias per axis (first-order
  Gauss-Markov: steady-state std ``*_bias_sigma``, correlation time ``*_bias_tau_s``; the
  turn-on bias is drawn from the same distribution).
- **Magnetometer**: the earth field at home (:class:`MagField`: declination,
  inclination, strength) rotated into body FRD, in Gauss, plus white noise. The field is
  the same everywhere in the flight area (a few km at most).
- **Barometer**: static pressure of the ISA standard atmosphere at the true altitude
  AMSL (hPa), plus white noise and a slow Gauss-Markov drift (both in Pa); the ISA
  temperature at that altitude (deg C) with white noise; ``pressure_alt`` is the altitude
  the noisy pressure gives back through the same atmosphere.
- **Differential pressure** (optional, off by default): 0 hPa plus white noise (no
  airspeed model for a multicopter).
- **GPS** at a lower rate: latitude/longitude/altitude of the true position around the
  home :class:`~ft_sitl.frames.GeoReference` plus a Gauss-Markov wander and white noise
  (horizontal and vertical), NED velocity with white noise, ground speed and course over
  ground from that velocity, a nominal eph/epv (with a few cm of jitter), 10 satellites,
  3D fix.

**Values never repeat exactly.** PX4's sensor validator flags a sensor as stale when its
value stays the same (to 1e-6) about 100 times in a row (DataValidator,
VALUE_EQUAL_COUNT_DEFAULT). The noise makes an exact repeat practically impossible; on top
of that every measurement is rounded to its wire type here (float32 for HIL_SENSOR,
integers for HIL_GPS) and, should it still equal the previous frame's value, moved by
one unit in the last place (float32) or one count (integers). Status fields (fix type,
satellite count) are constant by design.

Everything is drawn from one ``numpy.random.Generator`` seeded by ``seed``: the same
seed and the same truth sequence give the same readings.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

from ft_sitl import G, frames
from ft_sitl.rotations import matrix_from_quat

# --- ISA standard atmosphere (troposphere) ------------------------------------------------
ISA_P0_PA = 101325.0  #: sea-level pressure
ISA_T0_K = 288.15  #: sea-level temperature
ISA_LAPSE_K_M = 0.0065  #: temperature lapse rate
R_DRY_AIR = 287.05287  #: specific gas constant of dry air, J/(kg K)
_ISA_EXP = G / (R_DRY_AIR * ISA_LAPSE_K_M)  # 5.2559


def isa_pressure_pa(alt_m: float) -> float:
    """Static pressure (Pa) of the ISA atmosphere at altitude alt_m (m AMSL, < 11 km)."""
    return ISA_P0_PA * (1.0 - ISA_LAPSE_K_M * alt_m / ISA_T0_K) ** _ISA_EXP


def isa_temperature_c(alt_m: float) -> float:
    """ISA temperature (deg C) at altitude alt_m (m AMSL, < 11 km)."""
    return ISA_T0_K - ISA_LAPSE_K_M * alt_m - 273.15


def isa_altitude_m(pressure_pa: float) -> float:
    """Altitude (m AMSL) at which the ISA atmosphere has the static pressure pressure_pa."""
    return ISA_T0_K / ISA_LAPSE_K_M * (1.0 - (pressure_pa / ISA_P0_PA) ** (1.0 / _ISA_EXP))


# --- earth magnetic field -----------------------------------------------------------------
@dataclass(frozen=True)
class MagField:
    """The earth's magnetic field at a place: declination (deg, east of true north
    positive), inclination (deg, field pointing down positive) and total strength (Gauss)."""

    declination_deg: float
    inclination_deg: float
    strength_gauss: float

    def __post_init__(self):
        for name, lo, hi in (("declination_deg", -180.0, 180.0),
                             ("inclination_deg", -90.0, 90.0),
                             ("strength_gauss", 0.1, 1.0)):
            v = getattr(self, name)
            if not isinstance(v, (int, float)) or not math.isfinite(v) or not lo <= v <= hi:
                raise ValueError(f"MagField.{name}: {v!r} is outside [{lo}, {hi}]")

    def ned(self) -> np.ndarray:
        """The field vector in NED (Gauss)."""
        dec, inc = math.radians(self.declination_deg), math.radians(self.inclination_deg)
        horizontal = self.strength_gauss * math.cos(inc)
        return np.array([horizontal * math.cos(dec), horizontal * math.sin(dec),
                         self.strength_gauss * math.sin(inc)])


#: The field at PX4 SITL's default home (47.397742 N, 8.545594 E): what PX4 itself expects
#: there, i.e. the bilinear interpolation of the WMM-2020 grid (epoch 2024.41) that PX4
#: compiles in (src/lib/world_magnetic_model/geo_magnetic_tables.hpp, looked up as
#: geo_mag_declination.cpp does): declination 3.406 deg, inclination 63.157 deg,
#: 48,239 nT. EKF2 rejects a magnetometer whose strength is off by more than 0.2 Gauss or
#: whose inclination is off by more than 20 deg (EKF2_MAG_CHK_STR / _INC), and takes the
#: declination from the same table, so matching it keeps PX4's heading right.
PX4_SITL_HOME_FIELD = MagField(declination_deg=3.406, inclination_deg=63.157,
                               strength_gauss=0.48239)


def mag_field_for_home(lat_deg: float, lon_deg: float) -> MagField:
    """The field we know for a home position: only PX4 SITL's default home has one built in;
    any other home needs its field passed explicitly."""
    lat0, lon0, _ = frames.PX4_SITL_HOME
    if abs(lat_deg - lat0) < 1e-6 and abs(lon_deg - lon0) < 1e-6:
        return PX4_SITL_HOME_FIELD
    raise ValueError(
        f"no magnetic field is built in for home {lat_deg:.7f}, {lon_deg:.7f}: pass "
        f"mag_field=MagField(declination_deg, inclination_deg, strength_gauss) with the WMM "
        f"values there (e.g. from NOAA's magnetic field calculator); PX4 refuses to arm when "
        f"the magnetometer disagrees with its own model at the GPS position")


# --- noise parameters ---------------------------------------------------------------------
@dataclass(frozen=True)
class SensorNoise:
    """Noise of every sensor (units in the names; ``*_density`` per sqrt(Hz), stds are
    one sigma; ``*_tau_s`` are Gauss-Markov correlation times). The defaults are of the
    order of Gazebo's SITL sensor plugins and keep PX4's pre-arm checks passing at rest
    (GPS drift well under EKF2_REQ_HDRIFT 0.1 m/s / EKF2_REQ_VDRIFT 0.2 m/s, eph under
    EKF2_REQ_EPH 3 m)."""

    accel_noise_density: float = 2.0e-3  # m/s^2/sqrt(Hz) -> 0.032 m/s^2 at 250 Hz
    accel_bias_sigma: float = 0.02  # m/s^2
    accel_bias_tau_s: float = 300.0
    gyro_noise_density: float = 2.0e-4  # rad/s/sqrt(Hz) -> 0.0032 rad/s at 250 Hz
    gyro_bias_sigma: float = 5.0e-4  # rad/s
    gyro_bias_tau_s: float = 300.0
    mag_noise_gauss: float = 0.002
    baro_noise_pa: float = 1.5  # about 0.13 m
    baro_drift_sigma_pa: float = 2.0
    baro_drift_tau_s: float = 300.0
    temperature_noise_c: float = 0.02
    diff_pressure_noise_hpa: float = 0.001
    gps_pos_noise_h_m: float = 0.02
    gps_pos_noise_v_m: float = 0.04
    gps_wander_sigma_h_m: float = 0.15
    gps_wander_sigma_v_m: float = 0.3
    gps_wander_tau_s: float = 60.0
    gps_vel_noise_h_m_s: float = 0.03
    gps_vel_noise_v_m_s: float = 0.05
    gps_eph_m: float = 0.9
    gps_epv_m: float = 1.2

    def __post_init__(self):
        for f in fields(self):
            v = getattr(self, f.name)
            if not isinstance(v, (int, float)) or not math.isfinite(v) or v < 0.0:
                raise ValueError(f"SensorNoise.{f.name}: {v!r} must be a finite number >= 0")
            if f.name.endswith("_tau_s") and v <= 0.0:
                raise ValueError(f"SensorNoise.{f.name}: {v!r} must be > 0 (seconds)")


# --- readings -----------------------------------------------------------------------------
@dataclass(frozen=True)
class HilSensorValues:
    """One IMU/mag/baro sample in HIL_SENSOR's units; every float is exactly a float32."""

    time_us: int
    accel_frd: tuple[float, float, float]  # m/s^2, specific force
    gyro_frd: tuple[float, float, float]  # rad/s
    mag_frd: tuple[float, float, float]  # Gauss
    abs_pressure_hpa: float
    diff_pressure_hpa: float
    pressure_alt_m: float
    temperature_c: float


@dataclass(frozen=True)
class GpsValues:
    """One GPS fix in HIL_GPS's integer units."""

    time_us: int
    lat_e7: int  # deg * 1e7
    lon_e7: int
    alt_mm: int  # AMSL
    eph_cm: int
    epv_cm: int
    vel_cm_s: int  # ground speed
    vn_cm_s: int
    ve_cm_s: int
    vd_cm_s: int
    cog_cdeg: int  # course over ground, 0..35999
    satellites: int
    fix_type: int  # 3 = 3D fix


GPS_SATELLITES = 10
GPS_FIX_3D = 3
_INT16 = (-32768, 32767)
_UINT16 = (0, 65534)  # 65535 means "unknown" in HIL_GPS


class _GaussMarkov:
    """First-order Gauss-Markov process per component: stationary std sigma, time constant
    tau; starts from a draw of the stationary distribution."""

    def __init__(self, rng: np.random.Generator, sigma, tau_s: float, n: int):
        self._rng = rng
        self.sigma = np.broadcast_to(np.asarray(sigma, dtype=float), (n,)).copy()
        self.tau_s = float(tau_s)
        self.value = self.sigma * rng.standard_normal(n)

    def step(self, dt_s: float) -> np.ndarray:
        if dt_s > 0.0:
            a = math.exp(-dt_s / self.tau_s)
            self.value = a * self.value + self.sigma * math.sqrt(1.0 - a * a) * \
                self._rng.standard_normal(len(self.value))
        return self.value


class _Distinct:
    """Rounds values to their wire type and keeps each channel from repeating its previous
    value exactly (one float32 ulp or one integer count away if it would)."""

    def __init__(self):
        self._prev: dict[str, np.ndarray] = {}

    def float32(self, name: str, values) -> np.ndarray:
        v = np.array(values, dtype=np.float32).reshape(-1)
        prev = self._prev.get(name)
        if prev is not None:
            same = v == prev
            if same.any():
                v[same] = np.nextafter(v[same], np.float32(np.inf))
        self._prev[name] = v.copy()
        return v

    def ints(self, name: str, values, lo: int, hi: int, *, wrap: bool = False) -> np.ndarray:
        raw = np.rint(np.asarray(values, dtype=float).reshape(-1))
        v = (np.mod(raw, hi + 1) if wrap else np.clip(raw, lo, hi)).astype(np.int64)
        prev = self._prev.get(name)
        if prev is not None:
            same = v == prev
            if same.any():
                if wrap:
                    v[same] = (v[same] + 1) % (hi + 1)
                else:
                    v[same] = np.where(v[same] < hi, v[same] + 1, v[same] - 1)
        self._prev[name] = v.copy()
        return v


def _rotate_ned_to_frd(q_ned_frd, v_ned) -> np.ndarray:
    """World NED vector into body FRD: the inverse rotation of the unit q_ned_frd."""
    # body -> world rotation matrix; its transpose maps world -> body
    return matrix_from_quat(q_ned_frd, normalise=False).T @ np.asarray(v_ned, dtype=float)


class SensorSuite:
    """IMU, magnetometer, barometer and GPS of one vehicle (see the module docstring).

    ``truth`` arguments are duck-typed like :class:`~ft_sitl.bridge.vehicle.BridgeVehicle`:
    ``position_ned()`` (m, relative to home), ``velocity_ned()``, ``q_ned_frd()``,
    ``gyro_frd()``, ``accel_frd()``.
    """

    def __init__(self, *, home=frames.PX4_SITL_HOME, mag_field: MagField | None = None,
                 noise: SensorNoise | None = None, seed: int = 0, imu_rate_hz: float = 250.0,
                 gps_rate_hz: float = 10.0, diff_pressure: bool = False):
        self.home = home if isinstance(home, frames.GeoReference) else frames.GeoReference(*home)
        self.mag_field = (mag_field if mag_field is not None
                          else mag_field_for_home(self.home.lat_deg, self.home.lon_deg))
        if not isinstance(self.mag_field, MagField):
            raise TypeError(f"mag_field: a MagField expected, got {type(mag_field).__name__}")
        self.noise = noise if noise is not None else SensorNoise()
        if not isinstance(self.noise, SensorNoise):
            raise TypeError(f"noise: a SensorNoise expected, got {type(noise).__name__}")
        for name, v in (("imu_rate_hz", imu_rate_hz), ("gps_rate_hz", gps_rate_hz)):
            if not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
                raise ValueError(f"{name}: {v!r} must be a positive number of Hz")
        if gps_rate_hz > imu_rate_hz:
            raise ValueError(f"gps_rate_hz {gps_rate_hz} exceeds imu_rate_hz {imu_rate_hz}")
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
            raise ValueError(f"seed: {seed!r} must be an integer >= 0")
        self.imu_rate_hz = float(imu_rate_hz)
        self.gps_rate_hz = float(gps_rate_hz)
        self.gps_period_us = int(round(1e6 / gps_rate_hz))
        self.diff_pressure = bool(diff_pressure)
        self.seed = int(seed)
        self._field_ned = self.mag_field.ned()
        n = self.noise
        self._rng = np.random.default_rng(self.seed)
        self._accel_std = n.accel_noise_density * math.sqrt(self.imu_rate_hz)
        self._gyro_std = n.gyro_noise_density * math.sqrt(self.imu_rate_hz)
        self._accel_bias = _GaussMarkov(self._rng, n.accel_bias_sigma, n.accel_bias_tau_s, 3)
        self._gyro_bias = _GaussMarkov(self._rng, n.gyro_bias_sigma, n.gyro_bias_tau_s, 3)
        self._baro_drift = _GaussMarkov(self._rng, n.baro_drift_sigma_pa, n.baro_drift_tau_s, 1)
        self._gps_wander = _GaussMarkov(
            self._rng, [n.gps_wander_sigma_h_m, n.gps_wander_sigma_h_m, n.gps_wander_sigma_v_m],
            n.gps_wander_tau_s, 3)
        self._distinct = _Distinct()
        self._last_imu_us: int | None = None
        self._last_gps_us: int | None = None
        self._next_gps_us: int | None = None

    def reset(self) -> None:
        """A new autopilot: the next :meth:`gps_due` is true at once. Biases, drifts and the
        random stream carry on (the same sensors, powered on again)."""
        self._last_imu_us = None
        self._last_gps_us = None
        self._next_gps_us = None

    # --- IMU, magnetometer, barometer ---------------------------------------------------
    def hil_sensor(self, truth, time_us: int) -> HilSensorValues:
        """One IMU/mag/baro sample of the truth at time_us."""
        n, rng = self.noise, self._rng
        dt = (time_us - self._last_imu_us) * 1e-6 if self._last_imu_us is not None else 0.0
        self._last_imu_us = int(time_us)
        accel = (np.asarray(truth.accel_frd(), dtype=float) + self._accel_bias.step(dt)
                 + self._accel_std * rng.standard_normal(3))
        gyro = (np.asarray(truth.gyro_frd(), dtype=float) + self._gyro_bias.step(dt)
                + self._gyro_std * rng.standard_normal(3))
        mag = (_rotate_ned_to_frd(truth.q_ned_frd(), self._field_ned)
               + n.mag_noise_gauss * rng.standard_normal(3))
        alt = self.home.alt_m - float(truth.position_ned()[2])
        pressure_pa = (isa_pressure_pa(alt) + float(self._baro_drift.step(dt)[0])
                       + n.baro_noise_pa * rng.standard_normal())
        temperature = isa_temperature_c(alt) + n.temperature_noise_c * rng.standard_normal()
        diff = n.diff_pressure_noise_hpa * rng.standard_normal() if self.diff_pressure else 0.0
        d = self._distinct
        accel32 = d.float32("accel", accel)
        gyro32 = d.float32("gyro", gyro)
        mag32 = d.float32("mag", mag)
        baro32 = d.float32("baro", [pressure_pa / 100.0, isa_altitude_m(pressure_pa),
                                    temperature])
        diff32 = d.float32("diff", [diff])[0] if self.diff_pressure else np.float32(0.0)
        return HilSensorValues(
            time_us=int(time_us),
            accel_frd=tuple(float(v) for v in accel32),
            gyro_frd=tuple(float(v) for v in gyro32),
            mag_frd=tuple(float(v) for v in mag32),
            abs_pressure_hpa=float(baro32[0]),
            diff_pressure_hpa=float(diff32),
            pressure_alt_m=float(baro32[1]),
            temperature_c=float(baro32[2]),
        )

    # --- GPS ------------------------------------------------------------------------------
    def gps_due(self, time_us: int) -> bool:
        """True when a GPS fix is due at time_us (the first call after a reset always is)."""
        return self._next_gps_us is None or time_us >= self._next_gps_us

    def gps(self, truth, time_us: int) -> GpsValues:
        """One GPS fix of the truth at time_us; schedules the next one a GPS period later."""
        n, rng = self.noise, self._rng
        if self._next_gps_us is None or time_us - self._next_gps_us >= self.gps_period_us:
            self._next_gps_us = int(time_us) + self.gps_period_us
        else:
            self._next_gps_us += self.gps_period_us
        dt = (time_us - self._last_gps_us) * 1e-6 if self._last_gps_us is not None else 0.0
        self._last_gps_us = int(time_us)
        white = rng.standard_normal(3) * np.array(
            [n.gps_pos_noise_h_m, n.gps_pos_noise_h_m, n.gps_pos_noise_v_m])
        p_ned = np.asarray(truth.position_ned(), dtype=float) + self._gps_wander.step(dt) + white
        lat, lon, alt = self.home.to_global(frames.ned_to_enu(p_ned))
        v_ned = np.asarray(truth.velocity_ned(), dtype=float) + rng.standard_normal(3) * np.array(
            [n.gps_vel_noise_h_m_s, n.gps_vel_noise_h_m_s, n.gps_vel_noise_v_m_s])
        d = self._distinct
        lat_lon = d.ints("latlon", [lat * 1e7, lon * 1e7], -(2**31), 2**31 - 1)
        alt_mm = d.ints("alt", [alt * 1000.0], -(2**31), 2**31 - 1)[0]
        vel = d.ints("vel", v_ned * 100.0, *_INT16)
        speed = d.ints("speed", [math.hypot(v_ned[0], v_ned[1]) * 100.0], *_UINT16)[0]
        cog_deg = math.degrees(math.atan2(v_ned[1], v_ned[0])) % 360.0
        cog = d.ints("cog", [cog_deg * 100.0], 0, 35999, wrap=True)[0]
        ep = d.ints("ep", [n.gps_eph_m * 100.0 + 2.0 * rng.standard_normal(),
                           n.gps_epv_m * 100.0 + 2.0 * rng.standard_normal()], 1, _UINT16[1])
        return GpsValues(
            time_us=int(time_us), lat_e7=int(lat_lon[0]), lon_e7=int(lat_lon[1]),
            alt_mm=int(alt_mm), eph_cm=int(ep[0]), epv_cm=int(ep[1]), vel_cm_s=int(speed),
            vn_cm_s=int(vel[0]), ve_cm_s=int(vel[1]), vd_cm_s=int(vel[2]), cog_cdeg=int(cog),
            satellites=GPS_SATELLITES, fix_type=GPS_FIX_3D,
        )
