"""The ArduCopter face against hostile or careless clients, over its TCP serial ports:
MAVLink 2 signing set up with SETUP_SIGNING (unsigned traffic refused on every link once
it is on), random and garbled bytes and out-of-range fields on every port (the vehicle
keeps answering and its heartbeat goes on), a heartbeat no request silences, and bad
parameter sets answered as ArduPilot answers them (GCS_Param.cpp)."""

import math
import os
import socket

import numpy as np
import pytest

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402
from pymavlink.dialects.v20 import ardupilotmega as apm  # noqa: E402

from ft_sitl.mavlink.ardupilot.server import tcp_ports  # noqa: E402
from ft_sitl.mavlink.server import CHUNK_US  # noqa: E402

from .ardupilot_harness import free_ardupilot_sitl, until, wait_armed, wait_msg  # noqa: E402

pytestmark = pytest.mark.e2e  # (tests/lanes.py: TCP)

MAV = mavutil.mavlink
KEY = bytes(range(1, 33))


def _connect(port: int, **kw):
    mavutil.set_dialect("ardupilotmega")
    conn = mavutil.mavlink_connection(f"tcp:127.0.0.1:{port}", source_system=250, **kw)
    assert conn.wait_heartbeat(timeout=60) is not None
    return conn


def _probe(conn, what: str = "") -> None:
    """A command the vehicle answers (REQUEST_MESSAGE AUTOPILOT_VERSION) and its ACK: over
    one TCP connection everything sent before it was handled before it."""
    conn.mav.command_long_send(1, 1, MAV.MAV_CMD_REQUEST_MESSAGE, 0,
                               MAV.MAVLINK_MSG_ID_AUTOPILOT_VERSION, 0, 0, 0, 0, 0, 0)
    wait_msg(conn, "COMMAND_ACK", lambda m: m.command == MAV.MAV_CMD_REQUEST_MESSAGE, 30,
             f"answering the probe {what}")


def test_setup_signing_refuses_unsigned_on_every_link():
    with free_ardupilot_sitl() as (server, k):
        gcs = _connect(tcp_ports(k)[0])
        other = _connect(tcp_ports(k)[1])  # SERIAL1, nobody's key
        try:
            gcs.mav.request_data_stream_send(1, 1, MAV.MAV_DATA_STREAM_ALL, 4, 1)
            gcs.set_mode("GUIDED")
            ts = 10**9
            gcs.mav.setup_signing_send(1, 1, KEY, ts)  # (unsigned: signing is off)
            gcs.setup_signing(KEY, sign_outgoing=True, initial_timestamp=ts + 1)
            _probe(gcs, "signed, after SETUP_SIGNING")
            hb = wait_msg(gcs, "HEARTBEAT", lambda m: m.get_srcSystem() == 1, 30)
            assert hb.get_signed()  # the vehicle signs now

            # unsigned arming from SERIAL1: dropped unanswered, the vehicle stays disarmed
            bad0 = server.bad_packets
            other.mav.command_long_send(1, 1, MAV.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0,
                                        0, 0, 0, 0)
            other.mav.command_long_send(1, 1, MAV.MAV_CMD_REQUEST_MESSAGE, 0,
                                        MAV.MAVLINK_MSG_ID_AUTOPILOT_VERSION, 0, 0, 0, 0,
                                        0, 0)
            until(lambda: server.bad_packets >= bad0 + 2, 30, "the unsigned commands dropped")
            _probe(gcs, "after the unsigned commands")
            assert not server.agents[0].cmd.armed
            while (m := other.recv_match(blocking=False)) is not None:
                assert m.get_type() != "COMMAND_ACK", m

            # signed arming is accepted; SETUP_SIGNING while armed is refused
            gcs.arducopter_arm()
            wait_armed(gcs)
            gcs.mav.setup_signing_send(1, 1, bytes(32), 0)
            wait_msg(gcs, "STATUSTEXT",
                     lambda m: m.text == "ERROR: Won't setup signing when armed", 30)
            gcs.arducopter_disarm()
            until(lambda: not server.agents[0].cmd.armed, 60, "disarmed")

            # an all-zero key (signed) turns signing off: unsigned traffic answered again
            gcs.mav.setup_signing_send(1, 1, bytes(32), 0)
            until(lambda: not server.agents[0].signing.active, 30, "signing off")
            gcs.disable_signing()
            _probe(gcs, "unsigned, signing off")
            _probe(other, "unsigned from SERIAL1, signing off")
        finally:
            gcs.close()
            other.close()


def _hostile_frames(rng, enc) -> list[bytes]:
    """Random bytes, garbled and truncated frames, frames with fields out of range."""
    bad = [math.nan, math.inf, -math.inf, 1e30, -1e30, 0.0, -1.0]

    def pick():
        return float(rng.choice(bad))

    out = []
    for j in range(400):
        kind = j % 8
        if kind == 0:
            out.append(rng.bytes(int(rng.integers(1, 300))))
            continue
        if kind == 1:
            m = apm.MAVLink_set_position_target_local_ned_message(
                0, 1, 1, int(rng.integers(0, 22)), int(rng.integers(0, 65536)),
                *[pick() for _ in range(11)])
        elif kind == 2:
            m = apm.MAVLink_set_position_target_global_int_message(
                0, 1, 1, int(rng.integers(0, 22)), int(rng.integers(0, 65536)),
                int(rng.integers(-2**31, 2**31)), int(rng.integers(-2**31, 2**31)),
                *[pick() for _ in range(9)])
        elif kind == 3:
            m = apm.MAVLink_command_long_message(
                1, 1, int(rng.choice([16, 20, 21, 22, 115, 176, 178, 179, 195, 201, 400,
                                      511, 512, 300, 31999])), 0, *[pick() for _ in range(7)])
        elif kind == 4:
            m = apm.MAVLink_param_set_message(
                1, 1, rng.choice([b"WPNAV_SPEED", b"ANGLE_MAX", b"NOPE"]),  # (0, -1 out of range)
                pick(), int(rng.integers(0, 12)))
        elif kind == 5:
            m = apm.MAVLink_mission_item_message(
                1, 1, int(rng.integers(0, 5)), int(rng.integers(0, 12)),
                int(rng.integers(0, 300)), int(rng.integers(0, 4)), 1,
                *[pick() for _ in range(7)])
        elif kind == 6:
            m = apm.MAVLink_set_mode_message(1, int(rng.integers(0, 256)),
                                             int(rng.integers(0, 2**32)))
        else:
            m = apm.MAVLink_mission_count_message(1, 1, int(rng.integers(0, 65536)),
                                                  int(rng.integers(0, 256)))
        data = bytearray(m.pack(enc))
        if rng.random() < 0.3:  # a corrupt byte (bad CRC, or a bad length)
            data[int(rng.integers(0, len(data)))] ^= int(rng.integers(1, 256))
        if rng.random() < 0.2:  # truncated: the next frame follows mid-frame
            data = data[: int(rng.integers(1, len(data)))]
        out.append(bytes(data))
    return out


def test_fuzz_on_every_port_leaves_the_vehicle_answering():
    rng = np.random.default_rng(46)
    with free_ardupilot_sitl(speed_factor=4.0) as (server, k):
        agent = server.agents[0]
        params_before = {n: v for n, v in agent.vehicle.ap_params.items()}
        enc = apm.MAVLink(None, 250, 190)
        for port in tcp_ports(k):
            with socket.create_connection(("127.0.0.1", port)) as s:
                for frame in _hostile_frames(rng, enc):
                    s.sendall(frame)
                s.sendall(b"\xfd\xff" + bytes(20))  # a frame cut off by the close
        # a frame's worth of garbage left in a connection that stays open meanwhile
        held = socket.create_connection(("127.0.0.1", tcp_ports(k)[0]))
        held.sendall(b"\xfe\xff\x00\x00")
        try:
            for port in tcp_ports(k):  # every port still answers, and still beats
                conn = _connect(port)
                try:
                    # a start byte and a length in garbage right before the probe: the
                    # probe is still found (framing.py)
                    conn.write(b"\xfd\xfd\x00garbage")
                    _probe(conn, f"on port {port}")
                    wait_msg(conn, "HEARTBEAT", lambda m: m.get_srcSystem() == 1, 30)
                finally:
                    conn.close()
        finally:
            held.close()
        assert server.bad_packets > 0
        assert np.isfinite(server.fleet.sim.x).all()
        assert np.isfinite(server.fleet.sim.w_cmd).all()
        assert {n: v for n, v in agent.vehicle.ap_params.items()} == params_before


def test_no_request_silences_the_heartbeat():
    """SET_MESSAGE_INTERVAL HEARTBEAT (-1, huge, NaN) is refused, REQUEST_DATA_STREAM
    stopping every stream leaves it alone: the vehicle beats once a simulated second on
    both links, counted where the server sends them (simulated clock, not this client's)."""
    with free_ardupilot_sitl(speed_factor=4.0) as (server, k):
        conn = _connect(tcp_ports(k)[0])
        try:
            conn.mav.request_data_stream_send(1, 1, MAV.MAV_DATA_STREAM_ALL, 0, 0)
            for interval in (-1.0, 1e30, math.nan, 2e6):
                conn.mav.command_long_send(1, 1, MAV.MAV_CMD_SET_MESSAGE_INTERVAL, 0,
                                           MAV.MAVLINK_MSG_ID_HEARTBEAT, interval, 0, 0, 0,
                                           0, 0)
                ack = wait_msg(conn, "COMMAND_ACK",
                               lambda m: m.command == MAV.MAV_CMD_SET_MESSAGE_INTERVAL, 30)
                assert ack.result in (MAV.MAV_RESULT_FAILED, MAV.MAV_RESULT_DENIED)
            sent = {0: [], 1: []}
            send_all = server.send_all

            def recording(vehicle, outs):
                for out in outs:
                    if out.msg.get_type() == "HEARTBEAT":
                        for link in (0, 1) if out.link is None else (out.link,):
                            sent[link].append(server.fleet.time_us)
                send_all(vehicle, outs)

            server.send_all = recording
            sim0 = server.fleet.time_us
            until(lambda: server.fleet.time_us - sim0 >= 5e6, 120,
                  "5 s of simulated time")
            sim1 = server.fleet.time_us
            del server.send_all
            for link in (0, 1):
                beats = [t for t in sent[link] if t <= sim1]
                gaps = np.diff([sim0, *beats])
                assert len(beats) >= 4 and gaps.max() <= 1e6 + CHUNK_US, (link, beats)
            wait_msg(conn, "HEARTBEAT", lambda m: m.get_srcSystem() == 1, 30)
        finally:
            conn.close()


def test_bad_parameter_sets_answered_as_arducopter():
    """An unknown name, NaN or inf: no answer at all (GCS_Param.cpp returns early); a value
    out of range: 'Param write denied' and the old value echoed; an integer parameter
    rounded and echoed with its own type."""
    with free_ardupilot_sitl() as (server, k):
        conn = _connect(tcp_ports(k)[0])
        ap = server.agents[0].vehicle.ap_params
        try:
            for name, value in ((b"NO_SUCH_PARAM", 1.0), (b"WPNAV_SPEED", math.nan),
                                (b"WPNAV_SPEED", math.inf)):
                conn.mav.param_set_send(1, 1, name, value, MAV.MAV_PARAM_TYPE_REAL32)
            conn.mav.param_request_read_send(1, 1, b"WPNAV_SPEED", -1)
            pv = wait_msg(conn, "PARAM_VALUE", timeout_s=30)  # the first answer: the read's
            assert (pv.param_id, pv.param_value) == ("WPNAV_SPEED", 1000.0)
            conn.mav.param_set_send(1, 1, b"WPNAV_SPEED", 1e9, MAV.MAV_PARAM_TYPE_REAL32)
            pv = wait_msg(conn, "PARAM_VALUE", lambda m: m.param_id == "WPNAV_SPEED", 30)
            assert pv.param_value == 1000.0 and ap["WPNAV_SPEED"] == 1000
            wait_msg(conn, "STATUSTEXT", lambda m: m.text == "Param write denied (WPNAV_SPEED)",
                     30)
            why = wait_msg(conn, "STATUSTEXT", lambda m: m.text.startswith("WPNAV_SPEED"), 30)
            assert why.text == "WPNAV_SPEED: 1e+09 not in 10..2000 cm/s"  # one STATUSTEXT
            # inside ArduCopter's range, outside what the controller flies (MPC_XY_CRUISE)
            conn.mav.param_set_send(1, 1, b"WPNAV_SPEED", 100, MAV.MAV_PARAM_TYPE_REAL32)
            why = wait_msg(conn, "STATUSTEXT", lambda m: m.text.startswith("WPNAV_SPEED"), 30)
            assert why.text == "WPNAV_SPEED: 100 not flown by ft-sitl"
            conn.mav.param_set_send(1, 1, b"RTL_ALT", 2000.6, MAV.MAV_PARAM_TYPE_REAL32)
            pv = wait_msg(conn, "PARAM_VALUE", lambda m: m.param_id == "RTL_ALT", 30)
            assert pv.param_value == 2001.0 and pv.param_type == MAV.MAV_PARAM_TYPE_INT32
            assert ap["RTL_ALT"] == 2001
        finally:
            conn.close()


def test_guided_commands_refused_as_copter_refuses_them():
    """CONDITION_YAW outside 0..360 or with param4 not 0/1, DO_CHANGE_SPEED without a
    positive speed: FAILED; a climb speed: UNSUPPORTED; DO_REPOSITION by COMMAND_LONG:
    UNSUPPORTED, by COMMAND_INT outside GUIDED without CHANGE_MODE: DENIED; a guided
    go-to (MISSION_ITEM current 2) outside GUIDED: MISSION_ACK ERROR."""
    with free_ardupilot_sitl() as (server, k):
        conn = _connect(tcp_ports(k)[0])
        try:
            def result(command, *p):
                conn.mav.command_long_send(1, 1, command, 0, *p)
                return wait_msg(conn, "COMMAND_ACK", lambda m: m.command == command, 30).result

            assert result(MAV.MAV_CMD_CONDITION_YAW, 400, 0, 1, 0, 0, 0, 0) == \
                MAV.MAV_RESULT_FAILED
            assert result(MAV.MAV_CMD_CONDITION_YAW, 90, 0, 1, 2, 0, 0, 0) == \
                MAV.MAV_RESULT_FAILED
            assert result(MAV.MAV_CMD_DO_CHANGE_SPEED, 1, 0, -1, 0, 0, 0, 0) == \
                MAV.MAV_RESULT_FAILED
            assert result(MAV.MAV_CMD_DO_CHANGE_SPEED, 2, 3, -1, 0, 0, 0, 0) == \
                MAV.MAV_RESULT_UNSUPPORTED
            assert result(MAV.MAV_CMD_DO_CHANGE_SPEED, 1, 3, -1, 0, 0, 0, 0) == \
                MAV.MAV_RESULT_ACCEPTED
            assert server.agents[0].cmd.cruise_speed == 3
            assert result(MAV.MAV_CMD_DO_REPOSITION, -1, 1, 0, 0, 47.4, 8.5, 10) == \
                MAV.MAV_RESULT_UNSUPPORTED
            assert server.agents[0].mode_name != "GUIDED"
            conn.mav.command_int_send(1, 1, MAV.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
                                      MAV.MAV_CMD_DO_REPOSITION, 0, 0, -1, 0, 0, 0,
                                      474000000, 85000000, 10)
            ack = wait_msg(conn, "COMMAND_ACK",
                           lambda m: m.command == MAV.MAV_CMD_DO_REPOSITION, 30)
            assert ack.result == MAV.MAV_RESULT_DENIED
            conn.mav.mission_item_send(1, 1, 0, MAV.MAV_FRAME_GLOBAL_RELATIVE_ALT,
                                       MAV.MAV_CMD_NAV_WAYPOINT, 2, 0, 0, 0, 0, 0,
                                       47.3978, 8.5456, 10)
            ack = wait_msg(conn, "MISSION_ACK", timeout_s=30)
            assert ack.type == MAV.MAV_MISSION_ERROR
            assert server.agents[0].cmd.mission == []  # (a request, not an upload)
        finally:
            conn.close()
