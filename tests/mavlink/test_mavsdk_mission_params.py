"""MAVSDK missions (upload, start, pause, resume, finish, download, clear) and parameters."""

import asyncio

import pytest
from mavsdk.asyncio.plugins.action import ActionAsync
from mavsdk.asyncio.plugins.mission import MissionAsync
from mavsdk.asyncio.plugins.param import ParamAsync
from mavsdk.asyncio.plugins.telemetry import TelemetryAsync
from mavsdk.plugins.mission import MissionItem, MissionPlan
from mavsdk.plugins.param import ParamError

from ft_sitl.autopilot.params import PARAMS

from .mavsdk_util import connect, first
from .sitl_harness import running_sitl

pytestmark = pytest.mark.e2e  # (tests/lanes.py)

LAT0, LON0 = 47.397742, 8.545594
M_PER_DEG_LAT = 111195.0


def item(north_m, east_m, alt_m, speed=3.0):
    import math

    lat = LAT0 + north_m / M_PER_DEG_LAT
    lon = LON0 + east_m / (M_PER_DEG_LAT * math.cos(math.radians(LAT0)))
    return MissionItem(lat, lon, alt_m, speed, True, float("nan"), float("nan"),
                       MissionItem.CameraAction.NONE, float("nan"), float("nan"), 1.0,
                       float("nan"), float("nan"), MissionItem.VehicleAction.NONE)


def test_mission_upload_start_pause_resume_finish_download_clear():
    async def fly():
        m, drone = await connect()
        action, tel = ActionAsync(drone), TelemetryAsync(drone)
        mission = MissionAsync(drone)
        await first(tel.subscribe_health(), lambda h: h.is_armable)
        plan = MissionPlan([item(10, 0, 4), item(10, 10, 5), item(0, 10, 4)])
        await mission.upload_mission(plan)
        down = await mission.download_mission()
        assert len(down.mission_items) == 3
        assert down.mission_items[1].latitude_deg == pytest.approx(plan.mission_items[1]
                                                                   .latitude_deg, abs=1e-7)
        assert down.mission_items[1].relative_altitude_m == pytest.approx(5.0, abs=0.01)
        await action.arm()
        await mission.start_mission()
        await first(mission.subscribe_mission_progress(), lambda p: p.current == 1, timeout=40)
        await mission.pause_mission()
        mode = await first(tel.subscribe_flight_mode(), lambda f: f.name == "HOLD")
        assert mode.name == "HOLD"
        assert not await mission.is_mission_finished()
        await asyncio.sleep(1.0)
        await mission.start_mission()  # resume
        await first(mission.subscribe_mission_progress(), lambda p: p.current == 3, timeout=60)
        assert await mission.is_mission_finished()
        pos = await first(tel.subscribe_position())
        assert pos.relative_altitude_m == pytest.approx(4.0, abs=0.5)
        await mission.clear_mission()
        down = await mission.download_mission()
        assert len(down.mission_items) == 0
        await action.land()
        await first(tel.subscribe_armed(), lambda a: not a, timeout=30)
        m.destroy()

    with running_sitl(speed_factor=3.0) as server:
        asyncio.run(fly())
        assert list(server.fleet.commanders[0].reached)[:3] == [0, 1, 2]


def test_parameters_get_set_get_all_and_bounds():
    async def run():
        m, drone = await connect()
        param = ParamAsync(drone)
        assert await param.get_param_float("MPC_XY_VEL_MAX") == pytest.approx(4.0)
        await param.set_param_float("MPC_XY_VEL_MAX", 3.5)
        assert await param.get_param_float("MPC_XY_VEL_MAX") == pytest.approx(3.5)
        assert await param.get_param_int("FT_GAIN_MODE") == 0
        await param.set_param_int("MC_AIRMODE", 1)
        assert await param.get_param_int("MC_AIRMODE") == 1
        # stored PX4 parameters (accepted and echoed, no effect on the flight)
        await param.set_param_int("COM_RCL_EXCEPT", 4)
        assert await param.get_param_int("COM_RCL_EXCEPT") == 4
        await param.set_param_float("MPC_XY_TRAJ_P", 0.75)
        assert await param.get_param_float("MPC_XY_TRAJ_P") == pytest.approx(0.75)
        all_params = await param.get_all_params()
        ints = {p.name: p.value for p in all_params.int_params}
        floats = {p.name: p.value for p in all_params.float_params}
        assert len(ints) + len(floats) == len(PARAMS)  # the whole list
        assert set(ints) == {n for n, s in PARAMS.items() if s.is_int}
        assert {"MIS_TAKEOFF_ALT", "RTL_RETURN_ALT", "COM_OF_LOSS_T"} <= set(floats)
        assert (ints["COM_RCL_EXCEPT"], ints["NAV_DLL_ACT"], floats["MPC_XY_TRAJ_P"]) == \
            (4, 0, pytest.approx(0.75))
        with pytest.raises(ParamError):
            await param.set_param_float("MPC_XY_VEL_MAX", 99.0)  # out of bounds: refused
        assert await param.get_param_float("MPC_XY_VEL_MAX") == pytest.approx(3.5)
        with pytest.raises(ParamError):
            await param.set_param_int("NAV_DLL_ACT", 7)  # PX4's range is 0..6
        assert await param.get_param_int("NAV_DLL_ACT") == 0
        with pytest.raises(ParamError):
            await param.get_param_float("NO_SUCH_PARAM")
        m.destroy()

    with running_sitl(speed_factor=1.0) as server:
        asyncio.run(run())
        assert server.fleet.params[0]["MPC_XY_VEL_MAX"] == 3.5
        assert server.fleet.params[0]["MC_AIRMODE"] == 1
        assert server.fleet.params[0]["COM_RCL_EXCEPT"] == 4
