#!/usr/bin/env python3
"""Upload and fly a three-waypoint mission with MAVSDK (native 4.x binding, sync API).

    ft-sitl sitl &
    python examples/mavsdk_mission.py [udpin://0.0.0.0:14540]
"""

import math
import sys
import time

from mavsdk import ComponentType, Configuration, Mavsdk
from mavsdk.plugins.action import Action
from mavsdk.plugins.mission import Mission, MissionItem, MissionPlan
from mavsdk.plugins.telemetry import Telemetry

HOME_LAT, HOME_LON = 47.397742, 8.545594  # PX4 SITL's default home


def waypoint(north_m: float, east_m: float, alt_m: float) -> MissionItem:
    lat = HOME_LAT + north_m / 111195.0
    lon = HOME_LON + east_m / (111195.0 * math.cos(math.radians(HOME_LAT)))
    return MissionItem(lat, lon, alt_m, 4.0, True, math.nan, math.nan,
                       MissionItem.CameraAction.NONE, math.nan, math.nan, 1.0, math.nan,
                       math.nan, MissionItem.VehicleAction.NONE)


def main(url: str) -> None:
    mavsdk = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
    mavsdk.add_any_connection(url)
    drone = mavsdk.first_autopilot(10.0)
    if drone is None:
        raise SystemExit(f"no autopilot found on {url}")
    action, mission, telemetry = Action(drone), Mission(drone), Telemetry(drone)
    while not telemetry.health().is_armable:
        time.sleep(0.2)
    plan = MissionPlan([waypoint(15, 0, 5), waypoint(15, 15, 6), waypoint(0, 15, 5)])
    print(f"-- uploading {len(plan.mission_items)} waypoints")
    mission.upload_mission(plan)
    print("-- arming and starting the mission")
    action.arm()
    mission.start_mission()
    last = -1
    while not mission.is_mission_finished():
        progress = mission.mission_progress()
        if progress.current != last:
            print(f"-- mission progress {progress.current}/{progress.total}")
            last = progress.current
        time.sleep(0.5)
    print("-- mission finished: returning to launch")
    action.return_to_launch()
    while telemetry.armed():
        time.sleep(0.5)
    print("-- landed and disarmed")
    mavsdk.destroy()


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "udpin://0.0.0.0:14540")
