"""What a client cannot break over the wire: a takeoff altitude below home, message
intervals that would silence the vehicle, a long stall of the server; and BATTERY_STATUS
for packs of more than ten cells. Real UDP sockets and pymavlink, as a client would.

The vehicles here run as PX4 instance 30 (ports 14570/14610), clear of the ports the
other MAVLink tests use, so they can run beside them."""

import math
import time

import pytest
from pymavlink.dialects.v20 import common as mav

from .sitl_harness import running_sitl
from .test_pymavlink_and_robustness import ack_of, wait_msg
from .test_pymavlink_and_robustness import client as pymavlink_client

pytestmark = pytest.mark.e2e  # (tests/lanes.py)

INSTANCE = 30
API_PORT = 14540 + INSTANCE  # where the vehicle's API link sends (MAVSDK's udpin port)
VEHICLE_PORT = 14580 + INSTANCE  # where it listens


def client():
    return pymavlink_client(API_PORT)


def texts_until(c, needle, timeout=10.0):
    seen = []
    end = time.time() + timeout
    while time.time() < end:
        m = c.recv_match(type="STATUSTEXT", blocking=True, timeout=0.5)
        if m is not None:
            seen.append(m.text)
            if needle in m.text:
                return seen
    raise AssertionError(f"no status text with {needle!r} within {timeout} s: {seen}")


def test_takeoff_below_home_climbs_to_the_minimum_takeoff_altitude():
    # MAVProxy's `takeoff 5` sends NAV_TAKEOFF with param7 = 5 (read by PX4 as AMSL, far
    # below the 488 m home) and zeros elsewhere; PX4 raises it to MIS_TAKEOFF_ALT above the
    # vehicle and climbs, instead of "taking off" to -483 m and disarming on the ground
    with running_sitl(speed_factor=2.0, base_instance=INSTANCE) as server:
        c = client()
        c.mav.command_long_send(1, 1, mav.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
        assert ack_of(c, mav.MAV_CMD_COMPONENT_ARM_DISARM).result == mav.MAV_RESULT_ACCEPTED
        c.mav.command_long_send(1, 0, mav.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 0, 5.0)
        assert ack_of(c, mav.MAV_CMD_NAV_TAKEOFF).result == mav.MAV_RESULT_ACCEPTED
        seen = texts_until(c, "Takeoff to")
        assert "Using minimum takeoff altitude: 2.50 m" in seen
        assert "Takeoff to 2.5 m above home" in seen[-1]
        texts_until(c, "Takeoff complete", timeout=15)
        # holds there (after a small overshoot), armed
        wait_msg(c, "GLOBAL_POSITION_INT", lambda m: abs(m.relative_alt - 2500) < 100)
        cmd = server.fleet.commanders[0]
        assert cmd.armed and cmd.mode_name == "AUTO.LOITER"
        # NaN (MAVSDK's takeoff): MIS_TAKEOFF_ALT above where the vehicle is, no complaint
        c.mav.command_long_send(1, 1, mav.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, math.nan,
                                math.nan, math.nan, math.nan)
        assert ack_of(c, mav.MAV_CMD_NAV_TAKEOFF).result == mav.MAV_RESULT_ACCEPTED
        seen = texts_until(c, "Takeoff to")
        assert not any("minimum" in t for t in seen)
        above = float(seen[-1].split("Takeoff to ")[1].split(" m")[0])
        assert above == pytest.approx(5.0, abs=0.3)


def test_battery_status_reports_cells_11_to_14_in_the_extension():
    # a 12S pack (5.45 kg): cells 1-10 in `voltages`, 11-12 in the MAVLink 2 extension
    # `voltages_ext`, whose unused cells are 0 (`voltages`' are UINT16_MAX), as PX4 sends
    with running_sitl(platform="5.45kg-JFRC", base_instance=INSTANCE) as server:
        assert server.fleet.commanders[0].battery.cells == 12
        c = client()
        c.mav.command_long_send(1, 1, mav.MAV_CMD_REQUEST_MESSAGE, 0,
                                mav.MAVLINK_MSG_ID_BATTERY_STATUS, 0, 0, 0, 0, 0, 0)
        bat = wait_msg(c, "BATTERY_STATUS", timeout=5)
        sys_status = wait_msg(c, "SYS_STATUS", timeout=5)
    cells = list(bat.voltages) + list(bat.voltages_ext[:2])
    assert all(mv == cells[0] for mv in cells) and 4100 <= cells[0] <= 4200  # full
    assert list(bat.voltages_ext[2:]) == [0, 0]
    assert sum(cells) == pytest.approx(sys_status.voltage_battery, abs=12)


def test_absent_cells_are_uint16_max_in_voltages_and_0_in_the_extension():
    from ft_sitl.mavlink.telemetry import _cell_voltages_mv

    assert _cell_voltages_mv(3.95, 4) == ([3950] * 4 + [65535] * 6, [0, 0, 0, 0])
    assert _cell_voltages_mv(3.95, 14) == ([3950] * 10, [3950] * 4)
    assert _cell_voltages_mv(0.0, 12) == ([0] * 10, [1, 1, 0, 0])  # a measured 0 is 1


def test_a_stalled_server_falls_behind_instead_of_bursting():
    # a 3 s blocking call in the server's event loop (as a suspended process or a slow
    # disk would stall it): afterwards it answers at once and simulates at its pace, with
    # at most MAX_CATCH_UP_S made up, instead of running the 3 s backlog in one burst
    from ft_sitl.mavlink.server import MAX_CATCH_UP_S

    with running_sitl(base_instance=INSTANCE) as server:
        c = client()
        wait_msg(c, "HEARTBEAT")
        stall = {}

        def block_once():
            if not stall:
                stall["sim_us"] = server.fleet.time_us
                time.sleep(3.0)
                stall["end"] = time.monotonic()

        server.on_chunk = block_once
        end = time.time() + 10
        while "end" not in stall and time.time() < end:
            time.sleep(0.01)
        assert "end" in stall, "the server never stalled"
        while c.recv_match(blocking=False) is not None:  # what came before and during
            pass
        c.mav.command_long_send(1, 1, mav.MAV_CMD_REQUEST_MESSAGE, 0,
                                mav.MAVLINK_MSG_ID_AUTOPILOT_VERSION, 0, 0, 0, 0, 0, 0)
        assert ack_of(c, mav.MAV_CMD_REQUEST_MESSAGE, timeout=1.0).result == \
            mav.MAV_RESULT_ACCEPTED
        time.sleep(max(0.0, stall["end"] + 1.0 - time.monotonic()))
        advanced_s = (server.fleet.time_us - stall["sim_us"]) / 1e6
        assert 0.6 <= advanced_s <= 1.0 + MAX_CATCH_UP_S + 0.25, advanced_s
        assert server.behind_s == pytest.approx(3.0 - MAX_CATCH_UP_S, abs=0.3)
        wait_msg(c, "HEARTBEAT", timeout=2.0)  # and the telemetry goes on
