"""The ArduPilot JSON bridge against a peer that speaks ArduPilot's side byte for byte.

Real UDP sockets on free loopback ports; the bridge serves in a thread, the peer (see
ardupilot_peer.py) packs servo packets as SIM_JSON does and reads the answers as its parser
does. No timing is asserted: every check is on simulated time and state.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import math
import threading

import numpy as np
import pytest

from ft_sitl import G
from ft_sitl.bridge.ardupilot import ArduPilotBridge, parse_servo_packet, run_ardupilot_bridge
from ft_sitl.bridge.ardupilot_frames import (
    FrameMatchError,
    match_frame,
    motor_mapping,
    motor_mapping_for,
)
from ft_sitl.bridge.ardupilot_params import ArduPilotParamsError, ardupilot_params, motor_fit
from ft_sitl.frames import yaw_enu_to_ned
from ft_sitl.physics.catalog import catalog, get_platform
from ft_sitl.physics.layouts import get_layout
from tests.bridge.ardupilot_peer import (
    COPTER_RATE_HZ,
    QUAD_PLUS,
    QUAD_X,
    ArduPilotParseError,
    ArduPilotPeer,
    frame_text,
    hover_pwm,
    mixer_signs,
    parse_sensors,
    read_param_file,
    servo_packet,
)

PLATFORM = "1.50kg-DJI"
OFF = [1000] * 4


def q_heading(yaw_enu: float) -> np.ndarray:
    """NED <- FRD quaternion of a level vehicle with this ENU yaw (0 = east = heading 90)."""
    yaw_ned = yaw_enu_to_ned(yaw_enu)
    return np.array([math.cos(yaw_ned / 2.0), 0.0, 0.0, math.sin(yaw_ned / 2.0)])


@contextlib.contextmanager
def serving(platform, **kw):
    """A bridge on a free loopback port, served by a thread, and a peer talking to it."""
    bridge = ArduPilotBridge(platform, host="127.0.0.1", port=0, **kw)
    bridge.open()
    thread = threading.Thread(target=bridge.run, daemon=True)
    thread.start()
    peer = ArduPilotPeer(bridge.address)
    try:
        yield bridge, peer
    finally:
        bridge.stop()
        thread.join(30.0)
        peer.close()
        bridge.close()
        assert not thread.is_alive(), "the bridge did not stop"


@pytest.fixture(scope="module")
def platform():
    return get_platform(PLATFORM)


def assert_compact_json(raw: bytes) -> dict:
    """Framed by newlines, one object, compact separators; returns the object."""
    assert raw.startswith(b"\n") and raw.endswith(b"\n") and raw.count(b"\n") == 2, raw
    assert b": " not in raw and b", " not in raw, raw
    obj = json.loads(raw)
    assert set(obj) == {"timestamp", "imu", "position", "quaternion", "velocity"}
    assert set(obj["imu"]) == {"gyro", "accel_body"}
    return obj


# --- protocol -------------------------------------------------------------------------------
@pytest.mark.e2e
def test_lockstep_one_answer_per_packet_and_time_advances_by_one_frame(platform):
    with serving(platform) as (bridge, peer):
        half_step_s = 0.5 / bridge.physics_hz
        for k in range(12):
            raw, st = peer.exchange(k, OFF)
            obj = assert_compact_json(raw)
            # what ArduPilot's parser reads is what the JSON says
            assert st.timestamp == obj["timestamp"]
            np.testing.assert_array_equal(st.gyro, obj["imu"]["gyro"])
            np.testing.assert_array_equal(st.accel_body, obj["imu"]["accel_body"])
            np.testing.assert_array_equal(st.position, obj["position"])
            np.testing.assert_array_equal(st.velocity, obj["velocity"])
            np.testing.assert_array_equal(st.quaternion, obj["quaternion"])
            assert st.timestamp == pytest.approx((k + 1) / COPTER_RATE_HZ, abs=1e-12)
            # the plant is on the physics grid point nearest the reported time
            assert abs(bridge.vehicle.time_us * 1e-6 - st.timestamp) <= half_step_s + 1e-12
        # a further packet gets the next frame's answer: nothing extra was queued
        _, st = peer.exchange(12, OFF)
        assert st.timestamp == pytest.approx(13 / COPTER_RATE_HZ, abs=1e-12)
        c = bridge.counters
        assert (c.packets, c.frames, c.replies, c.repeats, c.bad_packets) == (13, 13, 13, 0, 0)


@pytest.mark.e2e
def test_frame_rate_sets_the_step_and_a_change_continues_the_clock(platform):
    with serving(platform) as (bridge, peer):
        for k in range(5):
            _, st = peer.exchange(k, OFF, frame_rate=1000)
            assert st.timestamp == pytest.approx((k + 1) * 1e-3, abs=1e-12)
            assert bridge.vehicle.time_us == (k + 1) * 1000  # exact: 1 ms = 4 steps
        _, st = peer.exchange(5, OFF, frame_rate=400)
        assert st.timestamp == pytest.approx(5e-3 + 2.5e-3, abs=1e-12)
        assert bridge.vehicle.time_us == 7500


@pytest.mark.e2e
def test_repeated_frame_count_resends_the_answer_without_stepping(platform):
    up = [1700] * 4
    with serving(platform) as (bridge, peer):
        count, _ = peer.fly(0, 200, up)
        raw, st = peer.exchange(count, up)
        t_us = bridge.vehicle.time_us
        again, _ = peer.exchange(count, [1000] * 4)  # ArduPilot re-sends the same frame
        assert again == raw
        assert bridge.vehicle.time_us == t_us
        assert bridge.counters.repeats == 1
        _, nxt = peer.exchange(count + 1, up)
        assert nxt.timestamp == pytest.approx((count + 2) / COPTER_RATE_HZ, abs=1e-12)
        assert bridge.counters.frames == count + 2


@pytest.mark.e2e
def test_decreasing_frame_count_is_a_restart_vehicle_back_at_spawn(platform):
    with serving(platform) as (bridge, peer):
        count, st = peer.fly(100, 900, [1900] * 4)  # 0.75 s at full-ish power: climbing
        assert st.position[2] < -0.5 and st.velocity[2] < -1.0
        raw, st = peer.exchange(0, OFF)
        assert bridge.counters.restarts == 1
        assert st.timestamp == pytest.approx(1 / COPTER_RATE_HZ, abs=1e-12)
        np.testing.assert_allclose(st.position, 0.0, atol=1e-9)
        np.testing.assert_allclose(st.velocity, 0.0, atol=1e-9)
        np.testing.assert_allclose(st.quaternion, q_heading(bridge.vehicle.spawn_yaw),
                                   atol=1e-12)
        _, st = peer.exchange(1, OFF)
        assert st.timestamp == pytest.approx(2 / COPTER_RATE_HZ, abs=1e-12)


@pytest.mark.e2e
def test_16_and_32_channel_packets_fly_the_same(platform):
    pwm = [1650, 1640, 1660, 1655]
    states = []
    for channels in (16, 32):
        with serving(platform) as (bridge, peer):
            raws = [peer.exchange(k, pwm + [1500] * 12, channels=channels)[0]
                    for k in range(300)]
            states.append(raws)
            assert bridge.counters.frames == 300 and bridge.counters.bad_packets == 0
    assert states[0] == states[1]
    # unused channels (5..32) change nothing
    with serving(platform) as (bridge, peer):
        raws = [peer.exchange(k, pwm + [2000] * 28, channels=32)[0] for k in range(300)]
    assert raws == states[0]


@pytest.mark.e2e
def test_bad_packets_are_counted_logged_and_not_fatal(platform, caplog):
    caplog.set_level("WARNING", logger="ft_sitl.bridge.ardupilot")
    good = servo_packet(0, OFF)
    bad = [
        b"",
        b"\x1a",
        struct_pack_wrong_magic(),
        good[:-2],  # short
        good + b"\0\0",  # long
        servo_packet(0, OFF, channels=32)[:len(good)],  # 32-channel magic, 16-channel size
        servo_packet(0, OFF, frame_rate=0),
        b"hello ardupilot",
    ]
    with serving(platform) as (bridge, peer):
        for data in bad:
            peer.send_raw(data)
        _, st = peer.exchange(0, OFF)  # the first answer is to the first good packet
        assert st.timestamp == pytest.approx(1 / COPTER_RATE_HZ, abs=1e-12)
        c = bridge.counters
        assert (c.packets, c.bad_packets, c.frames, c.replies) == (len(bad) + 1, len(bad), 1, 1)
        peer_port = peer.sock.getsockname()[1]
    messages = [r.getMessage() for r in caplog.records]
    assert len(messages) == len(bad)
    assert all(f"from 127.0.0.1:{peer_port}" in m for m in messages)
    assert any("magic 12345 is neither 18458 (16 channels) nor 29569" in m for m in messages)


def struct_pack_wrong_magic() -> bytes:
    data = bytearray(servo_packet(0, OFF))
    data[0:2] = (12345).to_bytes(2, "little")
    return bytes(data)


def test_servo_packet_errors_name_what_is_wrong():
    with pytest.raises(ValueError, match="magic 12345 is neither 18458"):
        parse_servo_packet(struct_pack_wrong_magic())
    with pytest.raises(ValueError, match="announces a 40-byte packet, got 38"):
        parse_servo_packet(servo_packet(0, OFF)[:-2])
    with pytest.raises(ValueError, match="frame_rate 0"):
        parse_servo_packet(servo_packet(0, OFF, frame_rate=0))
    pkt = parse_servo_packet(servo_packet(7, [1100, 1200, 1300, 1400], frame_rate=1200))
    assert (pkt.frame_rate_hz, pkt.frame_count, pkt.pwm_us[:5]) == (1200, 7, (1100, 1200, 1300,
                                                                              1400, 0))


def test_peer_parser_rejects_what_ardupilot_cannot_read():
    """The peer is strict where ArduPilot is: a space after the colon breaks the vectors."""
    spaced = (b'\n{"timestamp": 0.1, "imu": {"gyro": [0, 0, 0], "accel_body": [0, 0, -9.8]}, '
              b'"position": [0, 0, 0], "quaternion": [1, 0, 0, 0], "velocity": [0, 0, 0]}\n')
    with pytest.raises(ArduPilotParseError, match="imu/gyro"):
        parse_sensors(frame_text(spaced))
    with pytest.raises(ArduPilotParseError, match="no newline before"):
        frame_text(b'{"timestamp":1}\n')


# --- the plant as ArduPilot sees it -----------------------------------------------------------
@pytest.mark.e2e
def test_at_rest_the_accelerometer_reads_one_g_up(platform):
    with serving(platform) as (bridge, peer):
        _, st = peer.fly(0, 60, OFF)
    np.testing.assert_allclose(st.accel_body, [0.0, 0.0, -G], atol=1e-9)
    np.testing.assert_allclose(st.gyro, 0.0, atol=1e-12)
    np.testing.assert_allclose(st.position, 0.0, atol=1e-12)
    np.testing.assert_allclose(st.quaternion, q_heading(bridge.vehicle.spawn_yaw), atol=1e-12)
    # facing north (heading 0) unless told otherwise
    np.testing.assert_allclose(st.quaternion, [1.0, 0.0, 0.0, 0.0], atol=1e-12)


@pytest.mark.e2e
def test_the_spawn_heading_is_north_unless_told_otherwise(platform):
    from ft_sitl.scenarios.families import build_scenario

    with serving(platform, spawn_heading_deg=90.0) as (_, peer):
        _, st = peer.fly(0, 10, OFF)
    np.testing.assert_allclose(st.quaternion, q_heading(0.0), atol=1e-12)  # east
    scenario = build_scenario("forest", 1, 0)
    assert ArduPilotBridge(platform, scenario=scenario, port=0).vehicle.spawn_yaw == \
        pytest.approx(scenario.start_yaw)  # a scenario's start heading by default
    turned = ArduPilotBridge(platform, scenario=scenario, port=0, spawn_heading_deg=-45.0)
    assert yaw_enu_to_ned(turned.vehicle.spawn_yaw) == pytest.approx(math.radians(-45.0))
    with pytest.raises(ValueError, match="spawn heading: nan"):
        ArduPilotBridge(platform, port=0, spawn_heading_deg=math.nan)


@pytest.mark.e2e
def test_accel_noise_is_seeded_and_off_by_default(platform):
    answers = []
    for seed in (3, 3, 4):
        with serving(platform, accel_noise_m_s2=0.02, seed=seed) as (_, peer):
            answers.append([peer.exchange(k, OFF)[1].accel_body for k in range(5)])
    np.testing.assert_array_equal(answers[0], answers[1])
    assert not np.array_equal(answers[0], answers[2])
    assert np.all(np.abs(np.array(answers[0]) - [0.0, 0.0, -G]) < 0.2)
    assert not np.allclose(answers[0], [0.0, 0.0, -G], atol=1e-6)


def _airborne_rates(bridge, peer, count, pwm, n_frames):
    """Restart the bridge's vehicle (frame_count 0 after a higher one), fly n frames."""
    peer.exchange(count, OFF)
    _, st = peer.fly(0, n_frames, pwm)
    return st


@pytest.mark.e2e
@pytest.mark.parametrize("layout, table", [("quad_x", QUAD_X), ("quad_plus", QUAD_PLUS)])
def test_one_ardupilot_motor_up_turns_the_way_its_mixer_factors_say(platform, layout, table):
    p = dataclasses.replace(platform, layout=layout)
    base = hover_pwm(read_param_file(ardupilot_params(p))) + 40  # a little above hover
    with serving(p) as (bridge, peer):
        for j, (roll_f, pitch_f, yaw_f) in enumerate(mixer_signs(table)):
            pwm = [base] * 4
            pwm[j] += 120
            st = _airborne_rates(bridge, peer, 10_000, pwm, 360)  # 0.3 s
            assert st.position[2] < -0.01, f"motor {j + 1}: did not take off"
            p_, q_, r_ = st.gyro
            rates = {"roll": (p_, roll_f), "pitch": (q_, pitch_f), "yaw": (r_, yaw_f)}
            big = max(abs(p_), abs(q_))
            for axis, (rate, factor) in rates.items():
                if abs(factor) < 1e-9:
                    # only gyroscopic coupling (J_zz - J_xx) r p reaches this axis
                    assert abs(rate) < 0.05 * big, f"motor {j + 1}: {axis} rate {rate}"
                else:
                    assert math.copysign(1.0, rate) == math.copysign(1.0, factor), (
                        f"{layout} motor {j + 1}: {axis} rate {rate:+.4f} rad/s, ArduPilot's "
                        f"factor {factor:+.3f}")
        assert bridge.counters.restarts == 4


def test_motor_mapping_is_computed_from_positions_and_spins():
    for name, frame_type in (("quad_x", 1), ("quad_plus", 0)):
        layout = get_layout(name)
        m = motor_mapping(layout.rotor_positions(0.2), layout.spins())
        assert (m.frame.frame_class, m.frame.frame_type) == (1, frame_type)
        assert m.ours_for_ardupilot == (0, 1, 2, 3)  # our layouts list PX4 = ArduPilot order
    # our rotors listed in another order: the mapping follows the geometry
    layout = get_layout("quad_x")
    perm = [2, 0, 3, 1]
    m = motor_mapping(layout.rotor_positions(0.2)[perm], layout.spins()[perm])
    assert [perm[i] for i in m.ours_for_ardupilot] == [0, 1, 2, 3]
    u = m.commands([1100, 1200, 1300, 1400])
    np.testing.assert_allclose(u[[m.ours_for_ardupilot[j] for j in range(4)]],
                               [0.1, 0.2, 0.3, 0.4])
    # below MOT_PWM_MIN (0 with MOT_SAFE_DISARM) is off, above MOT_PWM_MAX is full
    u = m.commands([0, 900, 2000, 2100])
    np.testing.assert_array_equal(u[[m.ours_for_ardupilot[j] for j in range(4)]],
                                  [0.0, 0.0, 1.0, 1.0])


def test_a_layout_ardupilot_has_no_frame_for_is_refused():
    layout = get_layout("quad_x")
    with pytest.raises(FrameMatchError, match="motor 1 sits at 45 deg .* counter-clockwise"):
        motor_mapping(layout.rotor_positions(0.2), -layout.spins())  # mirrored props
    az = np.radians(np.arange(6) * 60.0)
    hexa = np.stack([np.cos(az), np.sin(az), np.zeros(6)], axis=1) * 0.3
    with pytest.raises(FrameMatchError, match="4 motors, the layout 6 rotors"):
        motor_mapping(hexa, np.array([1, -1, 1, -1, 1, -1]))
    with pytest.raises(FrameMatchError, match="no rotor there"):
        match_frame(motor_mapping_for(get_platform(PLATFORM)).frame,
                    get_layout("quad_plus").rotor_positions(0.2), layout.spins())


# --- the parameter file ----------------------------------------------------------------------
@pytest.mark.parametrize("name", sorted(catalog()))
def test_param_file_describes_the_platform(name):
    p = get_platform(name)
    text = ardupilot_params(p)
    prm = read_param_file(text)
    assert all(len(line) < 100 for line in text.splitlines())  # ArduPilot's line buffer
    assert prm["FRAME_CLASS"] == 1 and prm["FRAME_TYPE"] == 1  # catalog: all quad_x
    assert (prm["MOT_PWM_MIN"], prm["MOT_PWM_MAX"], prm["MOT_PWM_TYPE"]) == (1000, 2000, 0)
    idle = p.rotor_speed_min_rad_s / p.rotor_speed_max_rad_s
    assert idle <= prm["MOT_SPIN_MIN"] <= 0.3  # AP_MotorsMulticopter::arming_checks
    assert prm["MOT_SPIN_ARM"] <= prm["MOT_SPIN_MIN"]
    assert prm["MOT_SPIN_MAX"] == 1.0
    assert 0.125 <= prm["MOT_THST_HOVER"] <= 0.6875
    assert prm["MOT_BAT_VOLT_MAX"] == 0
    assert 0.01 <= prm["ATC_RAT_RLL_P"] <= 0.5 and prm["ATC_RAT_RLL_P"] == prm["ATC_RAT_PIT_P"]
    u_h = p.hover_rotor_speed_rad_s / p.rotor_speed_max_rad_s
    u_ap = (hover_pwm(prm) - 1000) / 1000
    if motor_fit(p).hover_clipped:
        assert "WARNING" in text and u_ap < u_h
    else:
        assert u_ap == pytest.approx(u_h, abs=1.5e-3)  # ArduPilot hovers where the plant does


def test_param_file_for_a_plus_quad_and_refusals(platform):
    plus = dataclasses.replace(platform, layout="quad_plus")
    assert read_param_file(ardupilot_params(plus))["FRAME_TYPE"] == 0
    high_idle = dataclasses.replace(platform,
                                    rotor_speed_min_rad_s=0.35 * platform.rotor_speed_max_rad_s)
    with pytest.raises(ArduPilotParamsError, match="MOT_SPIN_MIN would be 0.38, above the 0.3"):
        ardupilot_params(high_idle)


@pytest.mark.e2e
@pytest.mark.parametrize("name", ["1.50kg-DJI", "0.75kg-UAV 2", "4.00kg-SunnySky"])
def test_hover_pwm_from_the_param_file_holds_altitude(name):
    p = get_platform(name)
    pwm = hover_pwm(read_param_file(ardupilot_params(p)))
    with serving(p) as (_, peer):
        count, st = peer.fly(0, 600, [pwm + 60] * 4)  # 0.5 s: off the ground, climbing
        assert st.position[2] < -0.05
        count, st0 = peer.fly(count, 600, [pwm] * 4)  # 0.5 s for the motors to settle
        count, st1 = peer.fly(count, 1800, [pwm] * 4)  # 1.5 s at ArduPilot's hover output
    assert abs(st1.velocity[2] - st0.velocity[2]) < 0.25  # m/s over 1.5 s
    assert st1.accel_body[2] == pytest.approx(-G, abs=0.2)
    assert st1.position[2] < -0.05  # still in the air
    np.testing.assert_allclose(st1.quaternion, [1, 0, 0, 0], atol=1e-9)  # level, no turn


@pytest.mark.e2e
def test_a_failed_motor_behind_ardupilots_outputs_tumbles_the_vehicle(platform):
    # ft-sitl bridge ardupilot --actuators: the imperfection sits between the autopilot's
    # motor outputs and the rotors (ft_sitl.physics.actuators)
    pwm = hover_pwm(read_param_file(ardupilot_params(platform)))
    rates = []
    for act in (None, {"fail_motor": 1, "fail_at_s": 0.5}):
        with serving(platform) as (bridge, peer):
            bridge.vehicle.sim.set_actuators(0, act)
            count, st0 = peer.fly(0, 600, [pwm + 60] * 4)  # 0.5 s: off the ground
            assert st0.position[2] < -0.05
            _, st = peer.fly(count, 180, [pwm + 60] * 4)  # 0.15 s more
            rates.append(np.abs(st.gyro).max())
            w = bridge.vehicle.sim.rotor_speeds(0)
        assert (w[0] < 0.1 * w.max()) == (act is not None)  # the failed motor spun down
    assert rates[0] < 0.05 and rates[1] > 1.0  # rad/s: level, then tumbling


@pytest.mark.e2e
def test_in_a_scenario_position_is_from_the_spawn_and_a_crash_lasts_until_restart(platform):
    from ft_sitl.scenarios.families import build_scenario

    # starts facing north, a wall across the way (version 1: its gap is 4-18 m aside)
    scenario = build_scenario("narrow_gap", 1, 0, version=1)
    with serving(platform, scenario=scenario) as (bridge, peer):
        count, st = peer.fly(0, 700, [1850] * 4)  # climb
        assert st.position[0] == pytest.approx(0.0, abs=1e-9) and st.position[2] < -0.2
        np.testing.assert_allclose(st.quaternion, q_heading(scenario.start_yaw), atol=1e-9)
        np.testing.assert_allclose(st.quaternion, [1.0, 0.0, 0.0, 0.0], atol=1e-9)  # north
        count, _ = peer.fly(count, 30, [1800, 1900, 1800, 1900])  # back motors up: nose down
        for _ in range(6000):  # forward (north) into the wall, open loop
            _, st = peer.exchange(count, [1800] * 4)
            count += 1
            if bridge.vehicle.crash is not None:
                break
        crash = bridge.vehicle.crash
        assert crash is not None and crash.what.startswith("wall"), crash
        assert st.position[0] > 5.0  # flew north from the spawn point
        np.testing.assert_array_equal(bridge.vehicle.motor_commands, [0.8] * 4)  # asked...
        _, st = peer.fly(count, 600, [1900] * 4)
        assert bridge.vehicle.crash is crash  # ...but the motors stay off: it falls
        assert st.position[2] > -0.5 or st.velocity[2] > 0.0
        _, st = peer.exchange(0, OFF)  # ArduPilot restarts
        assert bridge.vehicle.crash is None
        np.testing.assert_allclose(st.position, 0.0, atol=1e-9)


# --- running it --------------------------------------------------------------------------------
@pytest.mark.e2e
def test_run_ardupilot_bridge_writes_params_serves_and_stops(tmp_path):
    started = threading.Event()
    holder = {}
    lines = []

    def on_start(bridge):
        holder["bridge"] = bridge
        started.set()

    params = tmp_path / "ft.parm"
    result = {}
    thread = threading.Thread(target=lambda: result.update(run_ardupilot_bridge(
        PLATFORM, "narrow_gap:1", 0, 500.0, params_path=params, on_start=on_start,
        echo=lambda *a, **k: lines.append(" ".join(map(str, a))))), daemon=True)
    thread.start()
    assert started.wait(60.0), "the bridge did not start"
    bridge = holder["bridge"]
    peer = ArduPilotPeer(bridge.address)
    try:
        _, st = peer.fly(0, 50, OFF)
    finally:
        peer.close()
        bridge.stop()
        thread.join(30.0)
    assert not thread.is_alive()
    assert st.timestamp == pytest.approx(50 / COPTER_RATE_HZ, abs=1e-12)
    assert read_param_file(params.read_text())["FRAME_TYPE"] == 1
    assert result["counters"]["frames"] == 50 and result["frame"] == "quad X"
    assert result["achieved_speed_factor"] > 0
    assert result["sim_time_s"] == pytest.approx(50 / COPTER_RATE_HZ)
    assert result["crash"] is None
    assert any("--model JSON:127.0.0.1" in line for line in lines)
    assert any("scenario narrow_gap-01-s0" in line for line in lines)


def test_run_ardupilot_bridge_names_a_bad_scenario_or_platform():
    with pytest.raises(ValueError, match="'forest': expected FAMILY:INDEX"):
        run_ardupilot_bridge(PLATFORM, "forest", 0)
    with pytest.raises(ValueError, match="no-such-quad"):
        run_ardupilot_bridge("no-such-quad", None, 0)


@pytest.mark.e2e
def test_constructor_rejects_bad_arguments(platform):
    with pytest.raises(ValueError, match="speed_factor: 0 must be a positive number"):
        ArduPilotBridge(platform, speed_factor=0)
    with pytest.raises(ValueError, match="port: 70000"):
        ArduPilotBridge(platform, port=70000)
    with pytest.raises(RuntimeError, match="not open"):
        _ = ArduPilotBridge(platform, port=0).address
    with serving(platform) as (bridge, _):
        taken = bridge.address[1]
        with pytest.raises(OSError, match=f"cannot listen .* UDP 127.0.0.1:{taken}"):
            ArduPilotBridge(platform, port=taken).open()
