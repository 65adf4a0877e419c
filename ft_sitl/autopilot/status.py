"""What the virtual PX4 reads of its vehicle each tick and the codes it answers with.

:class:`VehicleState` is the estimator stage's output, the only view of the vehicle the
commander and its flight tasks get (never the plant's truth directly). The enums carry
MAVLink's own values, so the MAVLink layer can send a command result, a landed state or a
status text's severity as the autopilot produced it, without a translation table that
could drift.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

import numpy as np


class Result(IntEnum):
    """MAV_RESULT values, so the MAVLink layer can send them as they are."""

    ACCEPTED = 0
    TEMPORARILY_REJECTED = 1
    DENIED = 2
    UNSUPPORTED = 3
    FAILED = 4
    IN_PROGRESS = 5


class LandedState(IntEnum):
    """MAV_LANDED_STATE values."""

    UNDEFINED = 0
    ON_GROUND = 1
    IN_AIR = 2
    TAKEOFF = 3
    LANDING = 4


class Severity(IntEnum):
    """MAV_SEVERITY values for status texts."""

    EMERGENCY = 0
    ALERT = 1
    CRITICAL = 2
    ERROR = 3
    WARNING = 4
    NOTICE = 5
    INFO = 6


@dataclass
class VehicleState:
    """What the commander knows of the vehicle each tick (from the estimator stage)."""

    position: np.ndarray
    velocity: np.ndarray
    yaw: float
    on_ground: bool
    tilt: float = 0.0
