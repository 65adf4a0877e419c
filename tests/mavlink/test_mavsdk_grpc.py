"""The old gRPC MAVSDK-Python API (mavsdk-grpc wheel, its bundled mavsdk_server) flying
the SITL unmodified: action, telemetry, offboard, mission, params."""

import asyncio

import pytest
from mavsdk_grpc import System
from mavsdk_grpc.mission import MissionItem, MissionPlan
from mavsdk_grpc.offboard import PositionNedYaw, VelocityNedYaw

from .mavsdk_util import first
from .sitl_harness import running_sitl

pytestmark = pytest.mark.e2e  # (tests/lanes.py)


def test_grpc_api_takeoff_offboard_mission_params_land():
    async def fly():
        drone = System(port=50061)
        await drone.connect(system_address="udpin://0.0.0.0:14540")
        await first(drone.core.connection_state(), lambda s: s.is_connected)
        await first(drone.telemetry.health(), lambda h: h.is_armable
                    and h.is_global_position_ok and h.is_home_position_ok)
        assert await drone.param.get_param_float("MIS_TAKEOFF_ALT") == pytest.approx(2.5)
        await drone.param.set_param_float("MIS_TAKEOFF_ALT", 3.0)
        await drone.action.arm()
        await drone.action.takeoff()
        pos = await first(drone.telemetry.position(), lambda p: p.relative_altitude_m > 2.9)
        assert pos.relative_altitude_m == pytest.approx(3.0, abs=0.2)
        await drone.offboard.set_position_ned(PositionNedYaw(0.0, 0.0, -3.0, 0.0))
        await drone.offboard.start()
        await drone.offboard.set_velocity_ned(VelocityNedYaw(1.0, 0.0, 0.0, 0.0))
        await asyncio.sleep(2.0)
        v = await first(drone.telemetry.velocity_ned())
        assert v.north_m_s == pytest.approx(1.0, abs=0.15)
        await drone.offboard.stop()
        item = MissionItem(47.397742 + 5 / 111195.0, 8.545594, 3.0, 2.0, True, float("nan"),
                           float("nan"), MissionItem.CameraAction.NONE, float("nan"),
                           float("nan"), 1.0, float("nan"), float("nan"),
                           MissionItem.VehicleAction.NONE)
        await drone.mission.upload_mission(MissionPlan([item]))
        await drone.mission.start_mission()
        await first(drone.mission.mission_progress(), lambda p: p.current == 1 and p.total == 1,
                    timeout=40)
        assert await drone.mission.is_mission_finished()
        await drone.action.land()
        await first(drone.telemetry.armed(), lambda a: not a, timeout=40)
        drone._stop_mavsdk_server()

    with running_sitl(speed_factor=2.0) as server:
        asyncio.run(fly())
        assert server.fleet.params[0]["MIS_TAKEOFF_ALT"] == 3.0
