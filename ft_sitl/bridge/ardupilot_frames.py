"""ArduPilot's view of a platform: its motor frames (AP_MotorsMatrix layouts), the mapping
from our rotor order to ArduPilot's motor numbers, and the PWM range the bridge maps to
motor commands. Shared by the JSON bridge (:mod:`ft_sitl.bridge.ardupilot`) and the
parameter file (:mod:`ft_sitl.bridge.ardupilot_params`)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ft_sitl.physics.layouts import get_layout

#: The PWM range the bridge maps to motor commands 0..1; the parameter file sets
#: MOT_PWM_MIN / MOT_PWM_MAX to the same values.
PWM_OFF_US = 1000
PWM_FULL_US = 2000


def pwm_to_command(pwm_us: float) -> float:
    """One PWM width (µs) -> motor command: 1000 µs and below off, 2000 µs and above full."""
    u = (float(pwm_us) - PWM_OFF_US) / (PWM_FULL_US - PWM_OFF_US)
    return min(max(u, 0.0), 1.0)


# --- ArduPilot's motor order -----------------------------------------------------------
@dataclass(frozen=True)
class ArduPilotMotor:
    #: ArduPilot's convention (AP_MotorsMatrix): degrees clockwise from the nose, seen
    #: from above (90 = right), i.e. the azimuth in the body FRD frame
    angle_deg: float
    #: +1 counter-clockwise seen from above (AP_MOTORS_MATRIX_YAW_FACTOR_CCW), -1 clockwise
    spin: int


@dataclass(frozen=True)
class ArduPilotFrame:
    name: str
    frame_class: int  # FRAME_CLASS
    frame_type: int  # FRAME_TYPE
    motors: tuple[ArduPilotMotor, ...]  # motor 1 (servo channel 1) first


#: ArduCopter's quad frames (AP_MotorsMatrix::setup_quad_matrix), motor 1 first.
ARDUPILOT_FRAMES: tuple[ArduPilotFrame, ...] = (
    ArduPilotFrame("quad X", 1, 1, (
        ArduPilotMotor(45.0, +1),  # 1 front right, CCW
        ArduPilotMotor(-135.0, +1),  # 2 back left, CCW
        ArduPilotMotor(-45.0, -1),  # 3 front left, CW
        ArduPilotMotor(135.0, -1),  # 4 back right, CW
    )),
    ArduPilotFrame("quad plus", 1, 0, (
        ArduPilotMotor(90.0, +1),  # 1 right, CCW
        ArduPilotMotor(-90.0, +1),  # 2 left, CCW
        ArduPilotMotor(0.0, -1),  # 3 front, CW
        ArduPilotMotor(180.0, -1),  # 4 back, CW
    )),
)


class FrameMatchError(ValueError):
    """A motor layout that none of ArduPilot's frames in :data:`ARDUPILOT_FRAMES` matches."""


@dataclass(frozen=True)
class MotorMapping:
    frame: ArduPilotFrame
    #: ours_for_ardupilot[j]: the index, in our rotor order, of ArduPilot's motor j + 1
    ours_for_ardupilot: tuple[int, ...]

    @property
    def n_motors(self) -> int:
        return len(self.ours_for_ardupilot)

    def commands(self, pwm_us) -> np.ndarray:
        """Servo channel widths (channel 1 first) -> motor commands 0..1 in our order."""
        if len(pwm_us) < self.n_motors:
            raise ValueError(f"{len(pwm_us)} servo channels for {self.n_motors} motors")
        u = np.empty(self.n_motors)
        for j, i in enumerate(self.ours_for_ardupilot):
            u[i] = pwm_to_command(pwm_us[j])
        return u


def _azimuth_frd_deg(position_flu) -> float:
    # FLU (x forward, y left) -> clockwise-from-the-nose angle: atan2(right, forward)
    return math.degrees(math.atan2(-position_flu[1], position_flu[0]))


def _angle_diff_deg(a: float, b: float) -> float:
    return abs((a - b + 180.0) % 360.0 - 180.0)


def match_frame(frame: ArduPilotFrame, positions_flu, spins, *, tol_deg: float = 1.0
                ) -> tuple[int, ...]:
    """Our rotor for each of the frame's motors, matched by azimuth and spin direction.

    positions_flu: (n, 3) rotor hub positions in our order (body FLU); spins: +1 CCW / -1 CW
    seen from above, our order. Raises :class:`FrameMatchError` naming the first ArduPilot
    motor without a rotor of ours at its angle (within tol_deg) turning its way.
    """
    pos = np.asarray(positions_flu, dtype=float)
    spins = np.asarray(spins, dtype=float)
    if pos.ndim != 2 or pos.shape[1] != 3 or len(spins) != len(pos):
        raise ValueError(f"positions_flu must be (n, 3) with n spins, got {pos.shape} and "
                         f"{len(spins)} spins")
    if len(pos) != len(frame.motors):
        raise FrameMatchError(f"ArduPilot {frame.name} has {len(frame.motors)} motors, the "
                              f"layout {len(pos)} rotors")
    azimuths = [_azimuth_frd_deg(p) for p in pos]
    ours: list[int] = []
    for j, m in enumerate(frame.motors):
        hits = [i for i in range(len(pos))
                if _angle_diff_deg(azimuths[i], m.angle_deg) <= tol_deg and spins[i] == m.spin]
        if len(hits) != 1 or hits[0] in ours:
            turning = "counter-clockwise" if m.spin > 0 else "clockwise"
            have = ", ".join(f"{a:.1f} deg {'CCW' if s > 0 else 'CW'}"
                             for a, s in zip(azimuths, spins))
            raise FrameMatchError(
                f"ArduPilot {frame.name} motor {j + 1} sits at {m.angle_deg:g} deg clockwise "
                f"from the nose turning {turning}; the layout has "
                f"{'no' if not hits else 'no unique'} rotor there (rotors: {have})"
            )
        ours.append(hits[0])
    return tuple(ours)


def motor_mapping(positions_flu, spins) -> MotorMapping:
    """The first of ArduPilot's frames that the rotor geometry matches, and the mapping."""
    reasons = []
    for frame in ARDUPILOT_FRAMES:
        try:
            return MotorMapping(frame, match_frame(frame, positions_flu, spins))
        except FrameMatchError as exc:
            reasons.append(str(exc))
    raise FrameMatchError("no ArduPilot frame matches this motor layout: " + "; ".join(reasons))


def motor_mapping_for(platform) -> MotorMapping:
    """The ArduPilot frame and motor mapping for a platform's layout (refused if none fits)."""
    layout = get_layout(platform.layout)
    try:
        return motor_mapping(layout.rotor_positions(platform.arm_length_m), layout.spins())
    except FrameMatchError as exc:
        raise FrameMatchError(f"platform {platform.name!r} (layout {platform.layout!r}) cannot "
                              f"be flown by ArduPilot: {exc}") from None


# --- the state ArduPilot reads -----------------------------------------------------------
