#!/usr/bin/env python3
"""Take off, hover and land with plain pymavlink, as against PX4 SITL.

    ft-sitl sitl &
    python examples/pymavlink_takeoff_land.py [udpin:0.0.0.0:14540]
"""

import math
import sys
import time

from pymavlink import mavutil


def main(url: str) -> None:
    # pymavlink defaults to sysid 255 / compid 0: pick an id of our own
    link = mavutil.mavlink_connection(url, source_system=245, source_component=190)
    if link.wait_heartbeat(timeout=10) is None:
        raise SystemExit(f"no heartbeat on {url}")
    print(f"-- connected to system {link.target_system}, mode {link.flightmode}")
    link.set_mode("POSCTL")
    link.arducopter_arm()
    link.motors_armed_wait()
    print("-- armed; taking off to 3 m above home")
    home = link.recv_match(type="GLOBAL_POSITION_INT", blocking=True, timeout=5)
    alt_amsl = home.alt / 1000.0 - home.relative_alt / 1000.0 + 3.0
    link.mav.command_long_send(link.target_system, 1, mavutil.mavlink.MAV_CMD_NAV_TAKEOFF, 0,
                               0, 0, 0, math.nan, math.nan, math.nan, alt_amsl)
    ack = link.recv_match(type="COMMAND_ACK", blocking=True, timeout=5)
    print(f"-- takeoff ack: {mavutil.mavlink.enums['MAV_RESULT'][ack.result].name}")
    deadline = time.time() + 30
    while time.time() < deadline:
        m = link.recv_match(type="GLOBAL_POSITION_INT", blocking=True, timeout=2)
        if m is not None and m.relative_alt > 2900:
            print(f"-- at {m.relative_alt / 1000.0:.2f} m")
            break
    time.sleep(2)
    print("-- landing")
    link.mav.command_long_send(link.target_system, 1, mavutil.mavlink.MAV_CMD_NAV_LAND, 0,
                               0, 0, 0, 0, 0, 0, 0)
    link.motors_disarmed_wait()
    print("-- landed and disarmed")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "udpin:0.0.0.0:14540")
