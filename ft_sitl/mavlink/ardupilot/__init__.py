"""The ArduCopter face: the same virtual flight controller as ArduCopter 4.x shows itself
on the wire (``ft-sitl sitl --autopilot ardupilot``).

One concept per module: :mod:`.modes` (ArduCopter's mode numbers onto the commander's
behaviours), :mod:`.params` (ArduCopter's parameter names, declared once each),
:mod:`.parameters` (the parameter protocol as ArduPilot answers it), :mod:`.telemetry`
(HEARTBEAT, AUTOPILOT_VERSION and the messages only ArduPilot sends), :mod:`.streams`
(SRn_* stream groups, REQUEST_DATA_STREAM), :mod:`.fence` (FENCE_* over the flight
controller's geofence, SYS_STATUS's fence bits), :mod:`.rally` (RTL's return point by
RALLY_*), :mod:`.parm` (.parm files, ``--defaults``), :mod:`.commands` (arming, modes,
take-off as ArduCopter answers them), :mod:`.guided` (GUIDED's position targets with
ArduPilot's type-mask reading, its heading and go-to requests), :mod:`.signing`
(SETUP_SIGNING over all the links), :mod:`.agent` (the router), :mod:`.framing` and
:mod:`.server` (ArduPilot SITL's TCP serial ports and ``--out`` UDP targets). What differs
from ArduCopter, and why: docs/mavlink.md, "ArduCopter face".
"""
