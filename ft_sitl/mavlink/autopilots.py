"""The autopilots whose MAVLink face ft-sitl serves, by the name ``--autopilot`` takes
(``ft-sitl sitl``, ``ft-sitl campaign run --transport mavlink``): ``px4`` (this package:
PX4 SITL's UDP ports; a navigator flies offboard) and ``ardupilot``
(:mod:`ft_sitl.mavlink.ardupilot`: ArduCopter 4.x; a navigator flies GUIDED). Kept free of
imports so the command line's parser can name them cheaply."""

PX4, ARDUPILOT = "px4", "ardupilot"
#: every face, the default first
AUTOPILOTS = (PX4, ARDUPILOT)
DEFAULT_AUTOPILOT = PX4
