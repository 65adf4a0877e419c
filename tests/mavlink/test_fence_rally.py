"""Geofence and rally points over the wire, as PX4 SITL serves them: MAVSDK's geofence
upload and download round-trip; a breach in the air takes GF_ACTION and is reported (a
STATUSTEXT, the commander's breach list); MAVSDK's raw rally upload makes RTL land at the
nearest rally point; bad fence items are refused with a MAVLink result, never a crash;
plain MISSION_ITEM uploads and unsupported frames are answered as PX4 answers them."""

import asyncio
import math
import time

import pytest
from mavsdk.asyncio.plugins.action import ActionAsync
from mavsdk.asyncio.plugins.geofence import GeofenceAsync
from mavsdk.asyncio.plugins.mission_raw import MissionRawAsync
from mavsdk.asyncio.plugins.param import ParamAsync
from mavsdk.asyncio.plugins.telemetry import TelemetryAsync
from mavsdk.plugins.geofence import Circle, FenceType, GeofenceData, Point, Polygon
from mavsdk.plugins.mission_raw import MissionItem as RawItem
from pymavlink.dialects.v20 import common as mav

from ft_sitl.autopilot.params import ParamSet

from .mavsdk_util import connect, first
from .sitl_harness import running_sitl
from .test_pymavlink_and_robustness import client, wait_msg

pytestmark = pytest.mark.e2e  # (tests/lanes.py)

INSTANCE = 62  # (ports of its own: a test's leftover client cannot starve the next)
GIVEN = 68  # (the last test's own: the pymavlink client before it keeps 62's port)

LAT0, LON0 = 47.397742, 8.545594
M_PER_DEG_LAT = 111195.0


def latlon(north_m, east_m):
    return (LAT0 + north_m / M_PER_DEG_LAT,
            LON0 + east_m / (M_PER_DEG_LAT * math.cos(math.radians(LAT0))))


def point(north_m, east_m):
    return Point(*latlon(north_m, east_m))


def test_fence_and_rally_round_trip_a_breach_returns_to_the_nearest_rally_point():
    async def run():
        m, drone = await connect(14540 + INSTANCE)
        fence, raw, action = GeofenceAsync(drone), MissionRawAsync(drone), ActionAsync(drone)
        tel, param = TelemetryAsync(drone), ParamAsync(drone)
        square = Polygon([point(-15, -15), point(-15, 15), point(15, 15), point(15, -15)],
                         FenceType.INCLUSION)
        keep_out = Circle(point(0, -10), 3.0, FenceType.EXCLUSION)
        await fence.upload_geofence(GeofenceData([square], [keep_out]))
        down = await fence.download_geofence()
        assert len(down.polygons) == 1 and len(down.circles) == 1
        got = down.polygons[0].points[2]
        assert (got.latitude_deg, got.longitude_deg) == pytest.approx(latlon(15, 15),
                                                                      abs=1e-7)
        assert down.circles[0].radius == pytest.approx(3.0)
        assert down.circles[0].fence_type == FenceType.EXCLUSION
        rally = [latlon(8, 8), latlon(-60, 0)]  # the first is nearer the breach than home
        await raw.upload_rally_points([
            RawItem(k, mav.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, mav.MAV_CMD_NAV_RALLY_POINT, 0,
                    1, 0, 0, 0, 0, round(la * 1e7), round(lo * 1e7), 0.0, 2)
            for k, (la, lo) in enumerate(rally)])
        assert len(await raw.download_rallypoints()) == 2
        await param.set_param_int("GF_ACTION", 3)  # return
        await first(tel.subscribe_health(), lambda h: h.is_armable)
        await action.set_takeoff_altitude(3.0)
        await action.arm()
        await action.takeoff()
        await first(tel.subscribe_position(), lambda p: p.relative_altitude_m > 2.8,
                    timeout=30)
        lat, lon = latlon(0, 25)  # east, out through the square's side
        await action.goto_location(lat, lon, 488.0 + 3.0, float("nan"))
        await first(tel.subscribe_flight_mode(), lambda f: f.name == "RETURN_TO_LAUNCH",
                    timeout=40)
        await first(tel.subscribe_armed(), lambda a: not a, timeout=60)
        pos = await first(tel.subscribe_position())
        await fence.clear_geofence()
        assert len((await fence.download_geofence()).polygons) == 0
        m.destroy()
        return pos

    # (a low return altitude: the return's climb and descent are not what is tested)
    with running_sitl(speed_factor=4.0, base_instance=INSTANCE,
                      params=[ParamSet({"RTL_RETURN_ALT": 5.0})]) as server:
        pos = asyncio.run(run())
        cmd = server.fleet.commanders[0]
        assert [(r, a) for _, r, a in cmd.fence_events] == [("outside the fence", "return")]
        texts = [t for _, t in cmd.statustexts]
        assert "Geofence breached: outside the fence" in texts
        assert "RTL: land at rally point" in texts
        assert (pos.latitude_deg, pos.longitude_deg) == pytest.approx(latlon(8, 8), abs=4e-6)
        assert cmd.fence.empty


def _upload(c, items, mtype, count=None):
    """A fence/rally upload by hand: MISSION_COUNT, then each requested item; the ack."""
    c.mav.mission_count_send(1, 1, len(items) if count is None else count, mtype)
    end = time.time() + 10
    while time.time() < end:
        m = c.recv_match(type=["MISSION_REQUEST_INT", "MISSION_REQUEST", "MISSION_ACK"],
                         blocking=True, timeout=1)
        if m is None:
            continue
        if m.get_type() == "MISSION_ACK":
            return m
        send = items[m.seq]
        send(c, m.seq)
    raise AssertionError("no MISSION_ACK")


def _vertex(n, north, east, cmd=mav.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION,
            frame=mav.MAV_FRAME_GLOBAL_INT):
    lat, lon = latlon(north, east)

    def send(c, seq):
        c.mav.mission_item_int_send(1, 1, seq, frame, cmd, 0, 1, n, 0, 0, 0,
                                    round(lat * 1e7) if math.isfinite(lat) else 0,
                                    round(lon * 1e7), 0.0, mav.MAV_MISSION_TYPE_FENCE)
    return send


def test_bad_fence_and_mission_items_get_a_mavlink_result_never_a_crash():
    with running_sitl(base_instance=INSTANCE) as server:
        c = client(14540 + INSTANCE)
        fence_t = mav.MAV_MISSION_TYPE_FENCE
        bowtie = [_vertex(4, 0, 0), _vertex(4, 10, 10), _vertex(4, 10, 0), _vertex(4, 0, 10)]
        assert _upload(c, bowtie, fence_t).type == mav.MAV_MISSION_INVALID
        two = [_vertex(2, 0, 0), _vertex(2, 10, 10)]
        assert _upload(c, two, fence_t).type == mav.MAV_MISSION_INVALID

        def nan_circle(c_, seq):
            c_.mav.mission_item_int_send(1, 1, seq, mav.MAV_FRAME_GLOBAL_INT,
                                         mav.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION, 0, 1,
                                         math.nan, 0, 0, 0, round(LAT0 * 1e7),
                                         round(LON0 * 1e7), 0.0, fence_t)
        assert _upload(c, [nan_circle], fence_t).type == mav.MAV_MISSION_INVALID
        assert _upload(c, [], fence_t, count=1000).type == mav.MAV_MISSION_NO_SPACE
        odd_frame = [_vertex(3, 0, 0, frame=mav.MAV_FRAME_BODY_FRD)]
        assert _upload(c, odd_frame, fence_t, count=3).type == \
            mav.MAV_MISSION_UNSUPPORTED_FRAME
        assert server.fleet.commanders[0].fence.empty  # nothing half-applied
        # a good one after all that
        square = [_vertex(4, -5, -5), _vertex(4, -5, 5), _vertex(4, 5, 5), _vertex(4, 5, -5)]
        assert _upload(c, square, fence_t).type == mav.MAV_MISSION_ACCEPTED
        assert len(server.fleet.commanders[0].fence.areas) == 1
        st = wait_msg(c, "SYS_STATUS", lambda m: m.onboard_control_sensors_present
                      & mav.MAV_SYS_STATUS_GEOFENCE)
        assert st.onboard_control_sensors_health & mav.MAV_SYS_STATUS_GEOFENCE  # not breached
        # plain MISSION_ITEM (float degrees), as MISSION_FLOAT is advertised
        lat, lon = latlon(10, 0)

        def float_wp(c_, seq):
            c_.mav.mission_item_send(1, 1, seq, mav.MAV_FRAME_GLOBAL_RELATIVE_ALT,
                                     mav.MAV_CMD_NAV_WAYPOINT, 0, 1, 0, 0, 0, math.nan,
                                     lat, lon, 5.0, 0)
        assert _upload(c, [float_wp], 0).type == mav.MAV_MISSION_ACCEPTED
        item = server.fleet.commanders[0].mission[0]
        # 10 m north, within float32 degrees' resolution (~0.4 m: why MISSION_ITEM_INT exists)
        assert item.position[1] == pytest.approx(10.0, abs=0.5)
        assert item.position[2] == pytest.approx(5.0)
        hb = wait_msg(c, "HEARTBEAT")  # still alive
        assert hb.autopilot == mav.MAV_AUTOPILOT_PX4


def test_a_fence_the_vehicle_was_given_without_an_upload_downloads_as_px4_stores_it():
    # a trial's fence (missions.protocol.trial_vehicle sets it on the commander before the
    # first step), as PX4 loads a fence file at boot: a ground station downloads its items
    from ft_sitl.autopilot.geofence import Fence, circle, polygon

    given = Fence([polygon([[-15.0, -15.0], [15.0, -15.0], [15.0, 15.0], [-15.0, 15.0]],
                           True, "trial"),
                   circle([-10.0, 0.0], 3.0, False, "trial")])

    async def run():
        m, drone = await connect(14540 + GIVEN)
        fence = GeofenceAsync(drone)
        down = await fence.download_geofence()
        assert [p.fence_type for p in down.polygons] == [FenceType.INCLUSION]
        got = [(p.latitude_deg, p.longitude_deg) for p in down.polygons[0].points]
        # ENU (x east, y north) -> latlon(north, east)
        want = [latlon(-15, -15), latlon(-15, 15), latlon(15, 15), latlon(15, -15)]
        assert got == [pytest.approx(w, abs=2e-7) for w in want]
        (c,) = down.circles
        assert (c.fence_type, c.radius) == (FenceType.EXCLUSION, pytest.approx(3.0))
        assert (c.point.latitude_deg, c.point.longitude_deg) == pytest.approx(
            latlon(0, -10), abs=2e-7)
        # uploaded back, the same fence (to the 1e-7 degree of the items, ~1 cm)
        await fence.upload_geofence(down)
        m.destroy()

    with running_sitl(base_instance=GIVEN) as server:
        cmd = server.fleet.commanders[0]
        cmd.set_fence(given)
        asyncio.run(run())
        back = cmd.fence
        assert back is not given and len(back.areas) == 2
        assert back.areas[0].vertices == pytest.approx(given.areas[0].vertices, abs=0.02)
        assert back.areas[1].center == pytest.approx(given.areas[1].center, abs=0.02)
        assert (back.areas[0].inclusion, back.areas[1].inclusion) == (True, False)
