"""pymavlink scripts, several vehicles at once, signing, tlog, and hostile input."""

import math
import time

import numpy as np
import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mav

from ft_sitl.mavlink.server import CHUNK_US

from .sitl_harness import running_sitl

pytestmark = pytest.mark.e2e  # (tests/lanes.py)


def client(port=14540, **kw):
    c = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", source_system=246,
                                   source_component=191, **kw)
    assert c.wait_heartbeat(timeout=10) is not None
    return c


def wait_msg(c, type_, cond=lambda m: True, timeout=20.0):
    end = time.time() + timeout
    while time.time() < end:
        m = c.recv_match(type=type_, blocking=True, timeout=0.5)
        if m is not None and cond(m):
            return m
    raise AssertionError(f"no {type_} matching within {timeout} s")


def ack_of(c, command, timeout=5.0):
    return wait_msg(c, "COMMAND_ACK", lambda m: m.command == command, timeout)


def test_pymavlink_set_mode_arm_takeoff_land():
    with running_sitl(speed_factor=2.0):
        c = client()
        hb = wait_msg(c, "HEARTBEAT")
        assert (hb.get_srcSystem(), hb.get_srcComponent()) == (1, 1)
        assert (hb.type, hb.autopilot) == (mav.MAV_TYPE_QUADROTOR, mav.MAV_AUTOPILOT_PX4)
        assert c.flightmode == "POSCTL"
        c.mav.command_long_send(1, 1, mav.MAV_CMD_REQUEST_MESSAGE, 0,
                                mav.MAVLINK_MSG_ID_AUTOPILOT_VERSION, 0, 0, 0, 0, 0, 0)
        ver = wait_msg(c, "AUTOPILOT_VERSION")
        assert ver.capabilities & mav.MAV_PROTOCOL_CAPABILITY_MISSION_INT
        assert ver.capabilities & mav.MAV_PROTOCOL_CAPABILITY_MAVLINK2
        c.set_mode("AUTO.LOITER" if "AUTO.LOITER" in c.mode_mapping() else "LOITER")
        wait_msg(c, "HEARTBEAT", lambda m: m.custom_mode == (4 << 16 | 3 << 24))
        c.arducopter_arm()
        assert ack_of(c, mav.MAV_CMD_COMPONENT_ARM_DISARM).result == mav.MAV_RESULT_ACCEPTED
        wait_msg(c, "HEARTBEAT", lambda m: m.base_mode & mav.MAV_MODE_FLAG_SAFETY_ARMED)
        c.mav.command_long_send(1, 1, mav.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, math.nan,
                                math.nan, math.nan, 488.0 + 4.0)
        assert ack_of(c, mav.MAV_CMD_NAV_TAKEOFF).result == mav.MAV_RESULT_ACCEPTED
        pos = wait_msg(c, "GLOBAL_POSITION_INT", lambda m: m.relative_alt > 3900)
        assert pos.relative_alt == pytest.approx(4000, abs=200)
        state = wait_msg(c, "EXTENDED_SYS_STATE")
        assert state.landed_state == mav.MAV_LANDED_STATE_IN_AIR
        c.set_mode_rtl()  # MAV_CMD_NAV_RETURN_TO_LAUNCH
        c.mav.command_long_send(1, 1, mav.MAV_CMD_NAV_LAND, 0, 0, 0, 0, 0, 0, 0, 0)
        assert ack_of(c, mav.MAV_CMD_NAV_LAND).result == mav.MAV_RESULT_ACCEPTED
        wait_msg(c, "HEARTBEAT", lambda m: not m.base_mode & mav.MAV_MODE_FLAG_SAFETY_ARMED,
                 timeout=120)  # (pymavlink's motors_disarmed_wait has no deadline)
        # unknown commands are answered, not ignored
        c.mav.command_long_send(1, 1, 31999, 0, 0, 0, 0, 0, 0, 0, 0)
        assert ack_of(c, 31999).result == mav.MAV_RESULT_UNSUPPORTED


def test_telemetry_reports_the_flight_controllers_estimate():
    # PX4 reports EKF2's estimate: with a biased estimator, so does ft-sitl; the truth
    # (on the spawn point, facing east) stays the plant's
    with running_sitl(estimator={"position_bias_m": [0.5, -0.3, 0.2],
                                 "attitude_bias_deg": [0.0, 0.0, 10.0]}) as server:
        c = client()
        lp = wait_msg(c, "LOCAL_POSITION_NED")
        assert (lp.x, lp.y, lp.z) == pytest.approx((-0.3, 0.5, -0.2), abs=1e-4)  # NED
        att = wait_msg(c, "ATTITUDE")
        assert math.degrees(att.yaw) == pytest.approx(90.0 - 10.0, abs=0.01)
        assert np.allclose(server.fleet.true_state(0).position, [0.0, 0.0, 0.0], atol=1e-3)


def test_commands_to_other_systems_are_ignored_and_acks_name_the_sender():
    with running_sitl():
        c = client()
        c.mav.command_long_send(7, 1, mav.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
        with pytest.raises(AssertionError):
            ack_of(c, mav.MAV_CMD_COMPONENT_ARM_DISARM, timeout=1.0)
        c.mav.command_long_send(1, 0, mav.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
        ack = ack_of(c, mav.MAV_CMD_COMPONENT_ARM_DISARM)
        assert ack.get_srcSystem() == 1 and ack.get_srcComponent() == 1
        assert (ack.target_system, ack.target_component) == (246, 191)


def test_several_vehicles_from_one_process_each_on_its_own_port():
    # One client at a time: a Python client that stops reading an onboard-rate link
    # (~400 messages/s, as PX4's) overflows its UDP receive buffer within a second.
    with running_sitl(instances=3) as server:
        for i in range(3):
            c = client(14540 + i)
            assert c.target_system == i + 1
            c.arducopter_arm()
            assert ack_of(c, mav.MAV_CMD_COMPONENT_ARM_DISARM).result == 0
            hb = wait_msg(c, "HEARTBEAT", lambda m: m.base_mode & mav.MAV_MODE_FLAG_SAFETY_ARMED)
            assert hb.get_srcSystem() == i + 1
            c.close()
        assert [cmd.armed for cmd in server.fleet.commanders] == [True] * 3
        # the GCS link of vehicle 2 answers a client that talks to it first
        g = mavutil.mavlink_connection("udpout:127.0.0.1:18571", source_system=247)
        g.mav.heartbeat_send(6, 8, 0, 0, 0)
        hb = wait_msg(g, "HEARTBEAT", lambda m: m.get_srcSystem() == 2)
        assert hb.base_mode & mav.MAV_MODE_FLAG_SAFETY_ARMED


def test_mission_upload_survives_wrong_sequence_and_abandonment():
    with running_sitl() as server:
        c = client()
        c.mav.mission_count_send(1, 1, 2, 0)
        req = wait_msg(c, "MISSION_REQUEST_INT")
        assert req.seq == 0
        # send item 1 first: the vehicle asks for 0 again
        c.mav.mission_item_int_send(1, 1, 1, 6, 16, 0, 1, 0, 1, 0, math.nan,
                                    473977420, 85455940, 5.0, 0)
        assert wait_msg(c, "MISSION_REQUEST_INT").seq == 0
        c.mav.mission_item_int_send(1, 1, 0, 6, 16, 0, 1, 0, 1, 0, math.nan,
                                    473977420, 85455940, 5.0, 0)
        assert wait_msg(c, "MISSION_REQUEST_INT").seq == 1
        # abandon: the vehicle re-requests, then gives up with an ack
        assert wait_msg(c, "MISSION_REQUEST_INT", timeout=4).seq == 1
        ack = wait_msg(c, "MISSION_ACK", timeout=15)
        assert ack.type == mav.MAV_MISSION_OPERATION_CANCELLED
        assert server.fleet.commanders[0].mission == []


def test_signing_rejects_unsigned_and_accepts_signed(tmp_path):
    from ft_sitl.mavlink.server import signing_secret

    with running_sitl(signing_key="correct horse") as server:
        plain = client()
        plain.arducopter_arm()
        time.sleep(1.0)
        assert not server.fleet.commanders[0].armed
        plain.close()
        signed = mavutil.mavlink_connection("udpin:127.0.0.1:14540", source_system=246,
                                            source_component=191)
        # after the first heartbeat: pymavlink replaces its protocol object (and would drop
        # the key) on the first MAVLink 2 packet it sees
        signed.wait_heartbeat(timeout=10)
        signed.setup_signing(signing_secret("correct horse"), sign_outgoing=True)
        signed.arducopter_arm()
        ack = ack_of(signed, mav.MAV_CMD_COMPONENT_ARM_DISARM)
        assert ack is not None and ack.result == mav.MAV_RESULT_ACCEPTED
        assert server.fleet.commanders[0].armed


def test_tlog_records_traffic_that_pymavlink_reads_back(tmp_path):
    log = tmp_path / "flight.tlog"
    with running_sitl(tlog=log):
        c = client()
        c.arducopter_arm()
        ack_of(c, mav.MAV_CMD_COMPONENT_ARM_DISARM)
        time.sleep(0.5)
    r = mavutil.mavlink_connection(str(log))
    types = set()
    while True:
        m = r.recv_match()
        if m is None:
            break
        types.add(m.get_type())
    assert {"HEARTBEAT", "COMMAND_LONG", "COMMAND_ACK", "ATTITUDE"} <= types


def test_hostile_input_never_crashes_the_vehicle():
    rng = np.random.default_rng(1234)
    k = 31  # PX4 instance 31: ports clear of the other MAVLink tests
    with running_sitl(speed_factor=4.0, base_instance=k) as server:
        c = client(14540 + k)
        sock = c.port
        dest = ("127.0.0.1", 14580 + k)
        enc = mav.MAVLink(None, 246, 191)
        good = [
            mav.MAVLink_command_long_message(1, 1, mav.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1,
                                             0, 0, 0, 0, 0, 0),
            mav.MAVLink_command_long_message(1, 1, mav.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0,
                                             math.nan, math.nan, math.nan, math.nan),
        ]
        for m in good:
            sock.sendto(m.pack(enc), dest)
        params_before = dict(server.fleet.params[0].items())
        bad_values = [math.nan, math.inf, -math.inf, 1e30, -1e30, 0.0]
        # hostile but valid: heartbeat intervals that would silence the vehicle
        silencers = [mav.MAVLink_command_long_message(
            1, 1, mav.MAV_CMD_SET_MESSAGE_INTERVAL, 0, mav.MAVLINK_MSG_ID_HEARTBEAT, v,
            0, 0, 0, 0, 0) for v in (1e30, math.inf, -1.0, -math.inf, math.nan, 2e6)]
        for j in range(600):
            kind = j % 6
            if kind == 0:  # random bytes
                sock.sendto(rng.bytes(int(rng.integers(1, 280))), dest)
                continue
            if kind == 1:  # hostile offboard setpoints
                v = [float(rng.choice(bad_values)) for _ in range(9)]
                m = mav.MAVLink_set_position_target_local_ned_message(
                    0, 1, 1, int(rng.integers(0, 16)), int(rng.integers(0, 4096)), *v,
                    float(rng.choice(bad_values)), float(rng.choice(bad_values)))
            elif kind == 2:  # commands with hostile params
                p = [float(rng.choice(bad_values)) for _ in range(7)]
                m = mav.MAVLink_command_long_message(
                    1, 1, int(rng.choice([16, 20, 21, 22, 176, 178, 179, 185, 192, 246, 300,
                                          400, 511, 512, 520])), 0, *p)
            elif kind == 3:  # attitude targets
                q = [float(rng.choice(bad_values)) for _ in range(4)]
                m = mav.MAVLink_set_attitude_target_message(
                    0, 1, 1, int(rng.integers(0, 256)), q, 0.0, 0.0, 0.0,
                    float(rng.choice(bad_values)))
            elif kind == 4:  # parameter sets of unknown names and absurd values
                m = mav.MAVLink_param_set_message(
                    1, 1, rng.choice([b"MPC_XY_VEL_MAX", b"NOPE", b"FT_GAIN_MODE"]),
                    float(rng.choice(bad_values[:5])), int(rng.integers(1, 11)))
            else:  # mission items out of the blue
                m = mav.MAVLink_mission_item_int_message(
                    1, 1, int(rng.integers(0, 5)), int(rng.integers(0, 12)),
                    int(rng.integers(0, 300)), 0, 1, *[float(rng.choice(bad_values))] * 4,
                    int(rng.integers(-2**31, 2**31)), int(rng.integers(-2**31, 2**31)),
                    float(rng.choice(bad_values)), 0)
            data = bytearray(m.pack(enc))
            if rng.random() < 0.2:  # corrupt a byte: bad CRC
                data[int(rng.integers(0, len(data)))] ^= 0xFF
            if rng.random() < 0.1:  # truncate
                data = data[: int(rng.integers(1, len(data)))]
            sock.sendto(bytes(data), dest)
            if j % 50 == 0:
                time.sleep(0.05)
                silencer = silencers[(j // 50) % len(silencers)]
                for link_port in (14580 + k, 18570 + k):  # both of the vehicle's links
                    sock.sendto(silencer.pack(enc), ("127.0.0.1", link_port))
        time.sleep(1.0)
        # still alive and answering, state finite. Our receive buffer overflowed while we
        # flooded without reading: drain it first, and retry as MAVSDK would
        while c.recv_match(blocking=False) is not None:
            pass
        ack = None
        for _ in range(3):
            c.mav.command_long_send(1, 1, mav.MAV_CMD_REQUEST_MESSAGE, 0, 245, 0, 0, 0, 0, 0, 0)
            try:
                ack = ack_of(c, mav.MAV_CMD_REQUEST_MESSAGE, timeout=2.0)
                break
            except AssertionError:
                continue
        assert ack is not None and ack.result == mav.MAV_RESULT_ACCEPTED
        assert np.isfinite(server.fleet.sim.x).all()
        assert np.isfinite(server.fleet.sim.w_cmd).all()
        assert server.bad_packets > 0
        # nothing silenced the vehicle: each silencer is refused (FAILED as PX4 answers
        # every heartbeat interval, DENIED for a non-finite one), and the vehicle sends a
        # heartbeat on both links at least once a simulated second. Counted where the server
        # sends them, against its simulated clock: a busy host slows the simulation and this
        # client, never the schedule (gaps in wall time between heartbeats received here
        # measured the host's load)
        for silencer in silencers:
            sock.sendto(silencer.pack(enc), dest)
            want = mav.MAV_RESULT_FAILED if math.isfinite(silencer.param2) else \
                mav.MAV_RESULT_DENIED
            assert ack_of(c, mav.MAV_CMD_SET_MESSAGE_INTERVAL).result == want
        sent = {0: [], 1: []}  # simulated time (us) of each heartbeat sent, by link
        send_all = server.send_all

        def recording(vehicle, outs):
            for out in outs:
                if out.msg.get_type() == "HEARTBEAT":
                    for link in (0, 1) if out.link is None else (out.link,):
                        sent[link].append(server.fleet.time_us)
            send_all(vehicle, outs)

        server.send_all = recording  # (read by the server's thread at each call)
        sim0 = server.fleet.time_us
        deadline = time.monotonic() + 120.0  # only against a hang: 5 s of simulated time
        while server.fleet.time_us - sim0 < 5e6 and time.monotonic() < deadline:
            time.sleep(0.05)
        sim1 = server.fleet.time_us  # (every heartbeat sent up to here is recorded)
        del server.send_all
        assert sim1 - sim0 >= 5e6, "the simulation did not advance 5 s in 120 s"
        for link in (0, 1):
            beats = [t for t in sent[link] if t <= sim1]
            gaps = np.diff([sim0, *beats])
            assert len(beats) >= 4 and gaps.max() <= 1e6 + CHUNK_US, (link, sim0, beats)
            assert sim1 - beats[-1] <= 1e6 + 2 * CHUNK_US, (link, sim1, beats)
        # ... and they reach the wire: this client still hears them
        while c.recv_match(blocking=False) is not None:
            pass
        wait_msg(c, "HEARTBEAT")
        # the parameters took none of the absurd values and still answer
        assert dict(server.fleet.params[0].items()) == params_before
        c.mav.param_request_read_send(1, 1, b"MPC_XY_VEL_MAX", -1)
        pv = wait_msg(c, "PARAM_VALUE", lambda m: m.param_id == "MPC_XY_VEL_MAX", timeout=5)
        assert pv.param_value == pytest.approx(params_before["MPC_XY_VEL_MAX"])


def test_timesync_param_rollback_and_per_vehicle_local_origin():
    with running_sitl(instances=2) as server:
        c = client(14541)
        c.mav.timesync_send(0, 123456789)
        ts = wait_msg(c, "TIMESYNC", lambda m: m.ts1 == 123456789)
        assert ts.tc1 > 0
        # each instance's local frame starts where it spawned (PX4 SITL), vehicle 2 is
        # 2 m north of vehicle 1 in the shared world
        lp = wait_msg(c, "LOCAL_POSITION_NED")
        assert abs(lp.x) < 0.01 and abs(lp.y) < 0.01
        # a value the platform cannot fly with is refused as a whole
        c.mav.param_set_send(2, 1, b"MPC_THR_MIN", 0.5, mav.MAV_PARAM_TYPE_REAL32)
        pv = wait_msg(c, "PARAM_VALUE", lambda m: m.param_id == "MPC_THR_MIN")
        assert pv.param_value == pytest.approx(0.12)
        assert server.fleet.params[1]["MPC_THR_MIN"] == pytest.approx(0.12)
        c.mav.param_set_send(2, 1, b"MPC_XY_VEL_MAX", 3.0, mav.MAV_PARAM_TYPE_REAL32)
        wait_msg(c, "PARAM_VALUE", lambda m: m.param_id == "MPC_XY_VEL_MAX"
                 and abs(m.param_value - 3.0) < 1e-6)
        assert server.bad_packets == 0
