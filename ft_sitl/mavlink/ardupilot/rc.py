"""RC input as ArduCopter reads it (libraries/RC_Channel/RC_Channel.cpp, RC_Channels.cpp,
GCS_Common.cpp's RC_CHANNELS_OVERRIDE): channel PWM values from RC_CHANNELS_OVERRIDE (what
MAVProxy's ``rc`` and DroneKit's ``vehicle.channels.overrides`` send), each timing out
RC_OVERRIDE_TIME seconds after its last value (-1 never, 0 overrides off), turned into
stick positions through RCMAP_ROLL/PITCH/THROTTLE/YAW and each channel's RCn_MIN/MAX/TRIM/DZ,
and handed to the flight controller as its manual inputs (the same path as the PX4 face's
MANUAL_CONTROL: one stick model).

Override fields as MAVLink and ArduPilot read them: channels 1..8 UINT16_MAX leaves the
channel as it is, 0 releases it to the radio; channels 9..18 0 or UINT16_MAX leave it,
UINT16_MAX - 1 releases it. Only the ground station ``SYSID_MYGCS`` may override.

The radio: until a client first overrides, the vehicle has no sticks (the stick modes hold
where they are, as before the face had RC). After that, a channel not overridden reads what
ArduPilot SITL's simulated radio reads: 1500 on every channel, the throttle channel at its
RCn_MIN (throttle low), so a LOITER or ALT_HOLD left alone by the client descends, as on
ArduPilot SITL.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # the vehicle owns this object; only its type is needed here
    from ft_sitl.mavlink.ardupilot.agent import ArduCopterVehicle

#: RC_CHANNELS_OVERRIDE's channels, and the channels with RCn_* parameters
OVERRIDE_CHANNELS, RC_CHANNELS = 18, 16
_IGNORE, _RELEASE_HIGH = 65535, 65534
#: what ArduPilot SITL's radio reads when nothing overrides a channel (us)
RADIO_CENTRE_PWM = 1500


class RcInput:
    """One vehicle's RC channels: the overrides in force and the sticks they make."""

    def __init__(self, v: ArduCopterVehicle):
        self.v = v
        #: per channel (index 0 = channel 1): (pwm, sim time us of its last value) or None
        self.overrides: list[tuple[int, int] | None] = [None] * OVERRIDE_CHANNELS
        #: a client has overridden a channel since the vehicle started (the radio is on)
        self.radio_on = False

    # --- input ---------------------------------------------------------------------------
    def on_override(self, m) -> None:
        """RC_CHANNELS_OVERRIDE from system ``m.get_srcSystem()``."""
        ap = self.v.ap_params
        if m.get_srcSystem() != ap["SYSID_MYGCS"] or ap["RC_OVERRIDE_TIME"] == 0:
            return
        now = self.v.fleet.time_us
        for k in range(OVERRIDE_CHANNELS):
            pwm = getattr(m, f"chan{k + 1}_raw", None)
            if pwm is None:  # (a MAVLink 1 message has 8 channels)
                break
            if k < 8:
                if pwm == _IGNORE:
                    continue
                release = pwm == 0
            else:
                if pwm in (0, _IGNORE):
                    continue
                release = pwm == _RELEASE_HIGH
            self.overrides[k] = None if release else (int(pwm), now)
            self.radio_on = True

    def clear(self) -> None:
        """Every override released (the GCS failsafe does this, RC_Channels::clear_overrides)."""
        self.overrides = [None] * OVERRIDE_CHANNELS

    # --- reading the channels --------------------------------------------------------------
    def _expire(self) -> None:
        timeout = self.v.ap_params["RC_OVERRIDE_TIME"]
        if timeout < 0:
            return
        now = self.v.fleet.time_us
        for k, o in enumerate(self.overrides):
            if o is not None and now - o[1] > timeout * 1e6:
                self.overrides[k] = None

    @property
    def overriding(self) -> bool:
        """Some channel is overridden now."""
        return any(o is not None for o in self.overrides)

    def pwm(self, channel: int) -> int:
        """Channel ``channel`` (1-based) now: its override, else the radio's value."""
        o = self.overrides[channel - 1]
        if o is not None:
            return o[0]
        if channel == int(self.v.ap_params["RCMAP_THROTTLE"]):
            return int(self.v.ap_params[f"RC{channel}_MIN"])
        return RADIO_CENTRE_PWM

    def _limits(self, channel: int) -> tuple[float, float, float, float]:
        ap = self.v.ap_params
        return (ap[f"RC{channel}_MIN"], ap[f"RC{channel}_MAX"], ap[f"RC{channel}_TRIM"],
                ap[f"RC{channel}_DZ"])

    def angle(self, channel: int) -> float:
        """An angle channel (roll, pitch, yaw) in -1..1, 0 within RCn_DZ of RCn_TRIM
        (RC_Channel::pwm_to_angle_dz_trim)."""
        lo, hi, trim, dz = self._limits(channel)
        pwm = self.pwm(channel)
        if pwm > trim + dz and hi > trim + dz:
            v = (pwm - trim - dz) / (hi - trim - dz)
        elif pwm < trim - dz and trim - dz > lo:
            v = (pwm - trim + dz) / (trim - dz - lo)
        else:
            v = 0.0
        return min(1.0, max(-1.0, v))

    def throttle(self) -> float:
        """The throttle channel in 0..1 from RCn_MIN (+ RCn_DZ) to RCn_MAX
        (RC_Channel::pwm_to_range_dz)."""
        ch = int(self.v.ap_params["RCMAP_THROTTLE"])
        lo, hi, _, dz = self._limits(ch)
        pwm = min(max(self.pwm(ch), lo), hi)
        if hi <= lo + dz or pwm <= lo + dz:
            return 0.0
        return (pwm - lo - dz) / (hi - lo - dz)

    def sticks(self) -> tuple[float, float, float, float]:
        """The sticks as the flight controller takes them: x pitch (forward +), y roll
        (right +), z throttle 0..1, r yaw (clockwise +). ArduPilot's pitch channel pitches
        forward below its trim."""
        ap = self.v.ap_params
        roll = self.angle(int(ap["RCMAP_ROLL"]))
        pitch = self.angle(int(ap["RCMAP_PITCH"]))
        yaw = self.angle(int(ap["RCMAP_YAW"]))
        return (-pitch, roll, self.throttle(), yaw)

    def tick(self) -> None:
        """Each chunk of simulated time: drop the overrides that timed out and, once the
        radio is on, give the flight controller the sticks."""
        self._expire()
        if not self.radio_on:
            return
        x, y, z, r = self.sticks()
        if all(math.isfinite(s) for s in (x, y, z, r)):
            self.v.fleet.manual_control(self.v.index, x, y, z, r)
