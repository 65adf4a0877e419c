"""The one place that converts between frames.

ft-sitl works in ENU (world: x east, y north, z up) and FLU (body: x forward, y left,
z up). MAVLink and PX4 use NED (world: x north, y east, z down) and FRD (body: x forward,
y right, z down). Geodetic conversions (local <-> latitude/longitude/altitude) join this
module with the MAVLink layer.
"""

from __future__ import annotations

import math

import numpy as np

from ft_sitl.rotations import qmul

# q_ned_enu: the fixed rotation that takes ENU vectors into NED (x<->y swap, z flip).
_Q_NED_ENU = np.array([0.0, math.sqrt(0.5), math.sqrt(0.5), 0.0])
# q_flu_frd: body FRD -> FLU is a rotation of pi about x.
_Q_FLU_FRD = np.array([0.0, 1.0, 0.0, 0.0])


def enu_to_ned(v_enu) -> np.ndarray:
    """Vector(s) in ENU to NED. Works on shape (3,) or (..., 3)."""
    v = np.asarray(v_enu, dtype=float)
    if v.ndim == 1:
        return np.array([v[1], v[0], -v[2]])
    return np.stack([v[..., 1], v[..., 0], -v[..., 2]], axis=-1)


def ned_to_enu(v_ned) -> np.ndarray:
    """Vector(s) in NED to ENU (the same swap is its own inverse)."""
    return enu_to_ned(v_ned)


def flu_to_frd(v_flu) -> np.ndarray:
    """Body vector(s) in FLU to FRD."""
    v = np.asarray(v_flu, dtype=float)
    if v.ndim == 1:
        return np.array([v[0], -v[1], -v[2]])
    return np.stack([v[..., 0], -v[..., 1], -v[..., 2]], axis=-1)


def frd_to_flu(v_frd) -> np.ndarray:
    return flu_to_frd(v_frd)


def yaw_enu_to_ned(yaw_enu: float) -> float:
    """ENU yaw (counter-clockwise from east) to NED yaw (clockwise from north), wrapped."""
    return wrap_pi(math.pi / 2.0 - yaw_enu)


def yaw_ned_to_enu(yaw_ned: float) -> float:
    return wrap_pi(math.pi / 2.0 - yaw_ned)


def wrap_pi(a: float) -> float:
    """Wrap an angle to [-pi, pi)."""
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def q_enu_flu_to_ned_frd(q_world_body) -> np.ndarray:
    """Attitude q_enu_flu (ENU world, FLU body) to q_ned_frd (PX4's attitude quaternion)."""
    q = qmul(qmul(_Q_NED_ENU, np.asarray(q_world_body, dtype=float)), _Q_FLU_FRD)
    return q if q[0] >= 0 else -q


def q_ned_frd_to_enu_flu(q_ned_frd) -> np.ndarray:
    q_enu_ned = _Q_NED_ENU * np.array([1.0, -1.0, -1.0, -1.0])
    q_frd_flu = _Q_FLU_FRD * np.array([1.0, -1.0, -1.0, -1.0])
    q = qmul(qmul(q_enu_ned, np.asarray(q_ned_frd, dtype=float)), q_frd_flu)
    return q if q[0] >= 0 else -q


# --- geodesy: local ENU <-> latitude / longitude / altitude --------------------------------
EARTH_RADIUS_M = 6371000.0  # the mean radius PX4's map projection uses
PX4_SITL_HOME = (47.397742, 8.545594, 488.0)  # PX4 SITL's default home (Zurich), deg/deg/m


class GeoReference:
    """Azimuthal equidistant projection about a reference point, as PX4's map_projection.

    Local ENU metres (x east, y north, z up from the reference altitude) to latitude and
    longitude (degrees) and altitude AMSL (metres), and back. Exact at the reference,
    well under a centimetre of error within the few kilometres a SITL flight covers.
    """

    def __init__(self, lat_deg: float, lon_deg: float, alt_m: float):
        for name, v, lo, hi in (("latitude", lat_deg, -90.0, 90.0),
                                ("longitude", lon_deg, -180.0, 180.0),
                                ("altitude", alt_m, -500.0, 10000.0)):
            if not isinstance(v, (int, float)) or not math.isfinite(v) or not lo <= v <= hi:
                raise ValueError(f"home {name}: {v!r} is outside [{lo}, {hi}]")
        self.lat_deg = float(lat_deg)
        self.lon_deg = float(lon_deg)
        self.alt_m = float(alt_m)
        self._lat = math.radians(lat_deg)
        self._lon = math.radians(lon_deg)
        self._sin_lat = math.sin(self._lat)
        self._cos_lat = math.cos(self._lat)

    def to_local(self, lat_deg: float, lon_deg: float, alt_m: float) -> np.ndarray:
        """(lat, lon, alt AMSL) -> ENU metres relative to the reference."""
        lat = math.radians(lat_deg)
        lon = math.radians(lon_deg)
        sin_lat, cos_lat = math.sin(lat), math.cos(lat)
        cos_dlon = math.cos(lon - self._lon)
        arg = min(1.0, max(-1.0, self._sin_lat * sin_lat + self._cos_lat * cos_lat * cos_dlon))
        c = math.acos(arg)
        k = c / math.sin(c) if abs(c) > 1e-12 else 1.0
        north = k * (self._cos_lat * sin_lat - self._sin_lat * cos_lat * cos_dlon) * EARTH_RADIUS_M
        east = k * cos_lat * math.sin(lon - self._lon) * EARTH_RADIUS_M
        return np.array([east, north, alt_m - self.alt_m])

    def to_global(self, p_enu) -> tuple[float, float, float]:
        """ENU metres -> (lat deg, lon deg, alt AMSL m)."""
        east, north, up = (float(v) for v in p_enu)
        x = north / EARTH_RADIUS_M
        y = east / EARTH_RADIUS_M
        c = math.hypot(x, y)
        if c > 1e-15:
            sin_c, cos_c = math.sin(c), math.cos(c)
            lat = math.asin(cos_c * self._sin_lat + x * sin_c * self._cos_lat / c)
            lon = self._lon + math.atan2(
                y * sin_c, c * self._cos_lat * cos_c - x * self._sin_lat * sin_c
            )
        else:
            lat, lon = self._lat, self._lon
        return math.degrees(lat), math.degrees(lon), self.alt_m + up
