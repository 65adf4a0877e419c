"""Where ArduCopter's RTL returns (libraries/AP_Rally/AP_Rally.cpp,
calc_best_rally_or_home_location): the nearest rally point (horizontally), unless there
is none, or RALLY_LIMIT_KM is above 0 and the nearest is farther than that (home), or
RALLY_INCL_HOME is 1 and home is nearer than it (home). PX4's rule (nearest of home and the
rally points, :func:`ft_sitl.autopilot.geofence.nearest_safe_point`) is RALLY_INCL_HOME 1
with no limit. The rally points are the mission protocol's RALLY list (MAV_CMD_NAV_RALLY_POINT)."""

from __future__ import annotations

import math

import numpy as np

from ft_sitl.mavlink.ardupilot.params import ApParamSet


class RallyRule:
    """The commander's return-point rule for one ArduCopter vehicle (its ``rally_rule``)."""

    def __init__(self, ap: ApParamSet):
        self.ap = ap

    def __call__(self, position, home, rally: list) -> np.ndarray:
        p = np.asarray(position, dtype=float)
        home = np.asarray(home, dtype=float)
        best, best_d = None, math.inf
        for r in rally:
            d = math.hypot(r[0] - p[0], r[1] - p[1])
            if d < best_d:
                best, best_d = np.asarray(r, dtype=float), d
        limit_m = self.ap["RALLY_LIMIT_KM"] * 1000.0
        if best is None or (limit_m > 0 and best_d > limit_m):
            return home.copy()
        if self.ap["RALLY_INCL_HOME"] and math.hypot(*(home[:2] - p[:2])) < best_d:
            return home.copy()
        return best.copy()
