"""Aggressiveness: the protocol's dynamic limits as named levels, one campaign axis.

A level is a name with the two dynamic limits the originals' configurations bound and our
planners model: the speed cap (``limits.max_speed_m_s``: what every planner plans with and
PX4's ``MPC_XY_VEL_MAX``) and the acceleration limit (``limits.max_acc_m_s2``: what every
planner plans with, protocol 3 on). EGO-Planner's and Fast-Planner's launch files (and so
PGO's, Fast-Planner's topological replanner) also set ``manager/max_jerk`` = 4, but no
planning step of either reads it (Fast-Planner's one jerk-bounded routine,
``fastLine4deg``, is called nowhere), so a level has no jerk.

:data:`LEVELS` declares the named levels once, from gentle to beyond the weakest catalog
platform's envelope; ``paper`` is the protocol's defaults, so a paper-level trial flies
exactly what a trial without the axis flies (docs/missions.md, "The aggressiveness
axis"). A campaign names levels or gives its own as tables; :func:`level_of` checks
either, with the ranges :data:`~ft_sitl.navigation.base.LIMITS` declares.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from ft_sitl.config import Table, did_you_mean
from ft_sitl.missions.spec import PROTOCOL_VERSION, PROTOCOLS, TrialSpecError
from ft_sitl.navigation.base import LIMITS, Limits

#: the limits a level sets (their units and ranges are LIMITS'), and a level table's keys
LEVEL_LIMITS = ("max_speed_m_s", "max_acc_m_s2")
LEVEL_KEYS = ("name", *LEVEL_LIMITS)


@dataclass(frozen=True)
class Level:
    """A named aggressiveness level: the speed cap (m/s) and the acceleration limit
    (m/s^2) a trial flies under; ``doc`` says where the numbers come from."""

    name: str
    max_speed_m_s: float
    max_acc_m_s2: float
    doc: str = ""

    def limits(self, base: Limits) -> Limits:
        """``base`` (the campaign's limits: timeout, goal sphere, hold) with this level's
        speed cap and acceleration limit."""
        return replace(base, max_speed_m_s=self.max_speed_m_s,
                       max_acc_m_s2=self.max_acc_m_s2)

    def as_dict(self) -> dict:
        """The level as data (campaign.json, ``campaign check --json``)."""
        return {"name": self.name, "max_speed_m_s": self.max_speed_m_s,
                "max_acc_m_s2": self.max_acc_m_s2}

    def summary(self) -> str:
        """``gentle (2 m/s, 2 m/s^2)``."""
        return f"{self.name} ({self.max_speed_m_s:g} m/s, {self.max_acc_m_s2:g} m/s^2)"


#: the named levels, gentle to aggressive (docs/missions.md, "The aggressiveness axis",
#: says why each)
LEVELS: dict[str, Level] = {lv.name: lv for lv in (
    Level("gentle", 2.0, 2.0,
          doc="the originals' released simulation configurations at their most cautious: "
              "EGO-Planner's 2 m/s with Fast-Planner's 2 m/s^2"),
    Level("paper", LIMITS["max_speed_m_s"].default, PROTOCOLS[PROTOCOL_VERSION].max_acc_m_s2,
          doc="the protocol's defaults: the paper's 4 m/s speed cap and the 3 m/s^2 every "
              "planner plans with from protocol 3 (a paper-level trial is a trial without "
              "the axis)"),
    Level("brisk", 6.0, 6.0,
          doc="the originals' real-world launch files' acceleration (up to 6 m/s^2), where "
              "the accel sweep's platforms with TWR <= 1.5 began to fail"),
    Level("aggressive", 8.0, 10.0,
          doc="beyond the weakest catalog platforms' envelope: at TWR 1.4 full thrust holds "
              "altitude up to g sqrt(TWR^2 - 1) = 9.6 m/s^2 horizontally, and PX4's 45 deg "
              "tilt limit caps every platform at g tan 45 deg = 9.8 m/s^2"),
)}


def level_names() -> str:
    """The declared levels in words: ``gentle (2 m/s, 2 m/s^2), paper (...), ...``."""
    return ", ".join(lv.summary() for lv in LEVELS.values())


def level_of(value, owner: str) -> Level:
    """The level ``value`` names (a declared level's name) or declares (a table ``{name,
    max_speed_m_s, max_acc_m_s2}``, each limit within LIMITS' range and the speed one the
    flight controller's MPC_XY_VEL_MAX takes). TrialSpecError naming ``owner``, the key
    and what is allowed."""
    if isinstance(value, str):
        if value not in LEVELS:
            raise TrialSpecError(f"{owner}: unknown aggressiveness level {value!r}"
                                 f"{did_you_mean(value, LEVELS)} (levels: {level_names()}; "
                                 f"or a table with {', '.join(LEVEL_KEYS)})")
        return LEVELS[value]
    if not isinstance(value, dict):
        raise TrialSpecError(f"{owner}: must be a level's name ({', '.join(LEVELS)}) or a "
                             f"table with {', '.join(LEVEL_KEYS)}, got {value!r}")
    t = Table(value, owner, error=TrialSpecError)
    t.check_keys(LEVEL_KEYS)
    t.require(LEVEL_KEYS)
    name = value["name"]
    if not isinstance(name, str) or not name.strip():
        raise t.fail("name", f"must be a non-empty string (the level's name in the rows), "
                             f"got {name!r}")
    for key in LEVEL_LIMITS:
        # LIMITS' parameter, but not none (the acceleration limit's default): a level sets it
        param = replace(LIMITS[key], default=LIMITS[key].range[0], nullable=False)
        try:
            param.check(value[key], owner)
        except ValueError as exc:
            raise TrialSpecError(str(exc)) from None
    level = Level(name, float(value["max_speed_m_s"]), float(value["max_acc_m_s2"]))
    known = LEVELS.get(name)
    if known is not None and known.as_dict() != level.as_dict():
        raise t.fail("name", f"{name!r} is a declared level, {known.summary()}: give the "
                             f"name alone for it, or another name for yours")
    return known or level
