"""An ArduCopter parameter file for flying one of our platforms through the JSON bridge.

What ArduPilot has to know about our vehicle, derived from the platform and our motor model,
with the reasoning in the file's comments (reference: docs/autopilot-in-the-loop.md):

- the frame (FRAME_CLASS / FRAME_TYPE) whose motor order the bridge maps to our rotors;
- the PWM range the bridge reads (MOT_PWM_MIN / MOT_PWM_MAX = 1000 / 2000 µs);
- the thrust curve. The bridge turns a PWM width into u = (pwm - 1000) / 1000, the plant
  commands the rotor speed u * w_max (never below idle while u > 0), and thrust goes with
  speed squared: T(u) = u^2 * T_max. ArduPilot's linearisation (AP_Motors_Thrust_
  Linearization) places its actuator a in [0, 1] between MOT_SPIN_MIN = s and
  MOT_SPIN_MAX = S, u = s + (S - s) a, and models normalised thrust as (1 - e) a + e a^2
  with e = MOT_THST_EXPO. Our T(u(a)) = T_0 + (T_1 - T_0) [(1 - e) a + e a^2] holds exactly
  with e = (S - s) / (S + s), T_0 = s^2 T_max, T_1 = S^2 T_max. So MOT_THST_EXPO is not 0
  (linear would be wrong for a quadratic plant) and not 1 either (the spin-min offset):
  0.739 for s = 0.15, S = 1. The only thing ArduPilot's curve leaves out is the thrust T_0
  at MOT_SPIN_MIN, which the hover value absorbs;
- MOT_THST_HOVER, the hover thrust in ArduPilot's normalised thrust:
  (u_h^2 - s^2) / (S^2 - s^2) with u_h = w_hover / w_max, so that ArduPilot's hover output
  is the PWM at which the plant hovers (ArduPilot keeps learning it: MOT_HOVER_LEARN);
- no battery-voltage compensation (our motors do not sag): MOT_BAT_VOLT_MAX = 0;
- roll and pitch rate gains scaled from ArduPilot's defaults by the platform's angular
  acceleration per unit of ArduPilot's roll / pitch output, so that the rate loops have the
  loop gain the defaults give ArduPilot's own SITL quad (a starting point, not a tune).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ft_sitl import G
from ft_sitl.bridge.ardupilot_frames import (
    PWM_FULL_US,
    PWM_OFF_US,
    ArduPilotFrame,
    motor_mapping_for,
)
from ft_sitl.physics.layouts import get_layout

# AP_MotorsMulticopter.h: MOT_THST_HOVER is constrained to this range
THST_HOVER_MIN = 0.125
THST_HOVER_MAX = 0.6875
# AP_MotorsMulticopter::arming_checks: "MOT_SPIN_MIN too high" above this
SPIN_MIN_LIMIT = 0.3
# ArduPilot's own default, used unless our idle speed needs more headroom
SPIN_MIN_DEFAULT = 0.15
SPIN_MAX = 1.0  # the plant saturates exactly at u = 1 (w_max)
# AC_AttitudeControl_Multi.h defaults and the documented ranges of the rate gains
RATE_RP_P, RATE_RP_I, RATE_RP_D = 0.135, 0.135, 0.0036
RATE_P_RANGE = (0.01, 0.5)


class ArduPilotParamsError(ValueError):
    """A platform that ArduCopter's motor parameters cannot describe."""


def _ref_alpha_rp() -> float:
    """Angular acceleration per unit roll output of ArduPilot's SITL default quad, flown X.

    libraries/SITL/SIM_Frame.cpp, Frame::init with the default Model: mass 3 kg, motors
    ``diagonal_size`` = 0.35 m from the centre (SIM_Motor::setup_params), inertia
    mass * 0.25 * (0.35 / 2)^2, hover at 0.39 of full thrust (hoverThrOut) with the same
    expo and spin range on the ArduPilot side, so its thrust span per motor is
    m g / (4 * 0.39). ArduPilot's X mixer puts +-0.5 per unit roll on each motor
    (normalise_rpy_factors), at a lever of 0.35 sin 45 deg.
    """
    mass, arm, hover_out = 3.0, 0.35, 0.39
    inertia = mass * 0.25 * (arm / 2.0) ** 2
    span = mass * G / (4.0 * hover_out)
    return 4.0 * 0.5 * span * arm * math.sin(math.radians(45.0)) / inertia


def _mixer_factors(frame: ArduPilotFrame) -> tuple[np.ndarray, np.ndarray]:
    """ArduPilot's roll and pitch factors per motor after normalisation to +-0.5."""
    ang = np.radians([m.angle_deg for m in frame.motors])
    roll, pitch = np.cos(ang + np.pi / 2.0), np.cos(ang)
    return 0.5 * roll / np.max(np.abs(roll)), 0.5 * pitch / np.max(np.abs(pitch))


@dataclass(frozen=True)
class MotorFit:
    """ArduPilot's view of the platform's motors (see the module docstring)."""

    idle_command: float  # w_min / w_max
    hover_command: float  # u_h = w_hover / w_max
    spin_arm: float
    spin_min: float
    spin_max: float
    thst_expo: float
    thst_hover_exact: float  # before ArduPilot's range limits
    thst_hover: float  # what the file sets (within 0.125..0.6875)

    @property
    def hover_clipped(self) -> bool:
        return self.thst_hover != round(self.thst_hover_exact, 4)


def motor_fit(platform) -> MotorFit:
    idle = platform.rotor_speed_min_rad_s / platform.rotor_speed_max_rad_s
    u_h = platform.hover_rotor_speed_rad_s / platform.rotor_speed_max_rad_s
    # thrust must start above our idle clamp: below idle the plant holds w_min
    s = max(SPIN_MIN_DEFAULT, math.ceil((idle + 0.03) * 100.0 - 1e-9) / 100.0)
    if s > SPIN_MIN_LIMIT:
        raise ArduPilotParamsError(
            f"platform {platform.name!r}: idle rotor speed is {idle:.3f} of maximum, so "
            f"MOT_SPIN_MIN would be {s:.2f}, above the {SPIN_MIN_LIMIT} ArduPilot accepts")
    if u_h <= s:
        raise ArduPilotParamsError(
            f"platform {platform.name!r}: hovers at {u_h:.3f} of maximum rotor speed, not "
            f"above MOT_SPIN_MIN {s:.2f}")
    spin_arm = min(math.ceil(idle * 100.0 - 1e-9) / 100.0, s)
    expo = (SPIN_MAX - s) / (SPIN_MAX + s)
    hover = (u_h**2 - s**2) / (SPIN_MAX**2 - s**2)
    return MotorFit(
        idle_command=idle, hover_command=u_h, spin_arm=spin_arm, spin_min=s,
        spin_max=SPIN_MAX, thst_expo=round(expo, 4), thst_hover_exact=hover,
        thst_hover=round(min(max(hover, THST_HOVER_MIN), THST_HOVER_MAX), 4))


def rate_gain_scale(platform) -> tuple[float, float]:
    """(roll, pitch): ArduPilot SITL quad's angular acceleration per unit roll/pitch output
    divided by the platform's (the factor applied to the default rate gains)."""
    fit = motor_fit(platform)
    mapping = motor_mapping_for(platform)
    layout = get_layout(platform.layout)
    pos = layout.rotor_positions(platform.arm_length_m)[list(mapping.ours_for_ardupilot)]
    x_frd, y_frd = pos[:, 0], -pos[:, 1]
    span = platform.rotor_thrust_max_n * (fit.spin_max**2 - fit.spin_min**2)
    roll_f, pitch_f = _mixer_factors(mapping.frame)
    # thrust along -z_FRD at (x, y): torque (-y T, x T, 0)
    tau_roll = float(np.sum(roll_f * span * -y_frd))
    tau_pitch = float(np.sum(pitch_f * span * x_frd))
    jxx, jyy, _ = platform.inertia_kg_m2
    ref = _ref_alpha_rp()
    return ref / (tau_roll / jxx), ref / (tau_pitch / jyy)


def _fmt(v: float) -> str:
    return str(int(v)) if float(v).is_integer() else f"{v:.6g}"


def ardupilot_params(platform) -> str:
    """The ArduCopter parameter file (``NAME VALUE`` lines, ``#`` comments) for a platform."""
    mapping = motor_mapping_for(platform)
    fit = motor_fit(platform)
    frame = mapping.frame
    lines: list[str] = []

    def com(text: str = "") -> None:
        lines.append(f"# {text}".rstrip())

    def par(name: str, value: float) -> None:
        lines.append(f"{name} {_fmt(value)}")

    com(f"ArduCopter parameters for the ft-sitl platform {platform.name!r},")
    com("flown through the ArduPilot JSON bridge (ft_sitl.bridge.ardupilot).")
    com("sim_vehicle.py ... --add-param-file=THIS, or arducopter ... --defaults THIS")
    com()
    com(f"Frame: ArduCopter {frame.name}. Bridge: ArduPilot motor -> our rotor "
        + ", ".join(f"{j + 1}->{i + 1}" for j, i in enumerate(mapping.ours_for_ardupilot)))
    par("FRAME_CLASS", frame.frame_class)
    par("FRAME_TYPE", frame.frame_type)
    com()
    com(f"The bridge reads {PWM_OFF_US} us as off and {PWM_FULL_US} us as full command.")
    par("MOT_PWM_TYPE", 0)
    par("MOT_PWM_MIN", PWM_OFF_US)
    par("MOT_PWM_MAX", PWM_FULL_US)
    com()
    com(f"Rotor speed command u * w_max; idle w_min = {fit.idle_command:.3f} w_max.")
    com("Armed on the ground: SPIN_ARM (at or below idle: the plant spins at idle);")
    com("thrust starts at SPIN_MIN (above idle); full rotor speed at SPIN_MAX = 1.")
    par("MOT_SPIN_ARM", fit.spin_arm)
    par("MOT_SPIN_MIN", fit.spin_min)
    par("MOT_SPIN_MAX", fit.spin_max)
    com()
    com("Thrust ~ u^2 with u = s + (S-s) a: ArduPilot's (1-e) a + e a^2 is exact")
    com(f"for e = (S-s)/(S+s) = {fit.thst_expo:.4f} (not 0: the plant is quadratic).")
    par("MOT_THST_EXPO", fit.thst_expo)
    com(f"Hover at u_h = {fit.hover_command:.4f} (TWR {1.0 / fit.hover_command**2:.2f}):")
    com(f"normalised hover thrust (u_h^2 - s^2)/(S^2 - s^2) = {fit.thst_hover_exact:.4f}.")
    if fit.hover_clipped:
        com(f"WARNING: outside ArduPilot's {THST_HOVER_MIN}..{THST_HOVER_MAX}; set to the")
        com("limit, the altitude controller's integrator must make up the rest. Expect")
        com("poor altitude control: ArduPilot assumes more thrust margin than this has.")
    par("MOT_THST_HOVER", fit.thst_hover)
    par("MOT_HOVER_LEARN", 2)
    com("No battery-voltage compensation: the plant's motors do not sag.")
    par("MOT_BAT_VOLT_MAX", 0)
    par("MOT_BAT_VOLT_MIN", 0)
    com()
    scale_roll, scale_pitch = rate_gain_scale(platform)
    com("Rate gains: ArduPilot's defaults (P 0.135, I 0.135, D 0.0036) times the ratio")
    com("of the angular acceleration per unit output of ArduPilot's SITL quad X")
    com(f"({_ref_alpha_rp():.0f} rad/s^2) to this platform's: roll x{scale_roll:.3f}, pitch")
    com(f"x{scale_pitch:.3f}, limited so that P stays within its documented")
    com(f"{RATE_P_RANGE[0]}..{RATE_P_RANGE[1]} (I and D keep the defaults' ratios to P).")
    com("A start, not a tune: yaw keeps ArduPilot's defaults; AUTOTUNE refines them.")
    for axis, scale in (("RLL", scale_roll), ("PIT", scale_pitch)):
        applied = min(max(scale, RATE_P_RANGE[0] / RATE_RP_P), RATE_P_RANGE[1] / RATE_RP_P)
        if applied != scale:
            com(f"{axis}: x{scale:.3f} limited to x{applied:.3f}")
        for kind, base in (("P", RATE_RP_P), ("I", RATE_RP_I), ("D", RATE_RP_D)):
            par(f"ATC_RAT_{axis}_{kind}", float(f"{base * applied:.4g}"))
    com()
    com("ArduPilot's physics frame rate (SITL default); the bridge steps 1/SIM_RATE_HZ")
    com("per servo packet.")
    par("SIM_RATE_HZ", 1200)
    return "\n".join(lines) + "\n"
