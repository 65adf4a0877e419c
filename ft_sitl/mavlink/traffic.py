"""Moving obstacles on the wire: one ADSB_VEHICLE per mover, as a traffic receiver hears
them, so a ground station or an avoidance client sees the world's movers as traffic."""

from __future__ import annotations

import math

from pymavlink.dialects.v20 import common as mav

from ft_sitl import frames
from ft_sitl.sim.fleet import Fleet

#: ADSB_VEHICLE, one per moving obstacle of the world (scenarios.movers), Hz: an ADS-B Out
#: transmitter's airborne position rate (two squitters a second). PX4 forwards each traffic
#: report its receiver gets, on every link ("unlimited" ADSB_VEHICLE stream); we play the
#: receiver, hearing every mover at this rate. Nothing is sent in a world without movers.
TRAFFIC_HZ = 2.0
#: the ICAO address of mover j is this + j + 1 (an arbitrary block: ADSB_FLAGS_SIMULATED
#: marks them as not real aircraft)
TRAFFIC_ICAO_BASE = 0xFE0000
#: the ADS-B emitter category of each mover shape (mover_kinds.SHAPES): a person has
#: none of its own (POINT_OBSTACLE), a box is a cart or a car (SERVICE_SURFACE), a sphere a
#: balloon or another drone (UAV)
TRAFFIC_EMITTER = {"person": mav.ADSB_EMITTER_TYPE_POINT_OBSTACLE,
                   "box": mav.ADSB_EMITTER_TYPE_SERVICE_SURFACE,
                   "sphere": mav.ADSB_EMITTER_TYPE_UAV}
TRAFFIC_FLAGS = (mav.ADSB_FLAGS_VALID_COORDS | mav.ADSB_FLAGS_VALID_ALTITUDE
                 | mav.ADSB_FLAGS_VALID_HEADING | mav.ADSB_FLAGS_VALID_VELOCITY
                 | mav.ADSB_FLAGS_VALID_CALLSIGN | mav.ADSB_FLAGS_SIMULATED)


def traffic_reports(fleet: Fleet, geo: frames.GeoReference) -> list:
    """One ADSB_VEHICLE per moving obstacle of the fleet's world (the collision guard's
    movers, where they are now), as a traffic receiver reports them: position (degE7) and
    altitude AMSL (mm) of the shape's centre, course over ground (cdeg from north) and
    horizontal speed (cm/s), the mover's name as the callsign ("PERSON2"), an emitter type
    by shape (TRAFFIC_EMITTER), flagged simulated. Empty without movers."""
    guard = fleet.guard
    movers = guard.movers if guard is not None else None
    if movers is None:
        return []
    t_us = fleet.time_us
    poses, vel = movers.poses(t_us), movers.velocities(t_us)
    out = []
    for j, info in enumerate(movers.describe()):
        lat, lon, alt = geo.to_global(poses[j, :3])
        course = math.degrees(frames.yaw_enu_to_ned(float(poses[j, 3]))) % 360.0
        speed = math.hypot(vel[j, 0], vel[j, 1])
        callsign = info["name"].replace(" ", "").upper()[:8].encode("ascii")
        out.append(mav.MAVLink_adsb_vehicle_message(
            TRAFFIC_ICAO_BASE + j + 1, int(round(lat * 1e7)), int(round(lon * 1e7)),
            mav.ADSB_ALTITUDE_TYPE_GEOMETRIC, int(round(alt * 1000)),
            int(round(course * 100)) % 36000, min(int(round(speed * 100)), 65535), 0,
            callsign, TRAFFIC_EMITTER[info["shape"]], 0, TRAFFIC_FLAGS, 0))
    return out
