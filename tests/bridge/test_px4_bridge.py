"""The PX4 bridge over real TCP, flown by a peer that speaks PX4's simulator link
(tests/bridge/px4_peer.py: pymavlink encoding, PX4's connect/answer sequence)."""

import dataclasses
import itertools
import math
from contextlib import contextmanager

import numpy as np
import pytest
import trimesh
from pymavlink.dialects.v20 import common as mav
from scipy.spatial.transform import Rotation

from ft_sitl import frames
from ft_sitl.bridge.px4 import (
    MotorMappingError,
    Px4Bridge,
    hover_output,
    px4_motor_map,
    px4_parameters,
    run_px4_bridge,
    scenario_from_spec,
)
from ft_sitl.bridge.sensors import (
    MagField,
    SensorNoise,
    SensorSuite,
    isa_altitude_m,
    isa_pressure_pa,
)
from ft_sitl.physics.catalog import get_platform
from ft_sitl.scenarios.scenario import Scenario

from .px4_peer import Px4Peer

PLATFORM = get_platform("0.98kg-EGO Planner DIY")
HOME_LAT, HOME_LON, HOME_ALT = frames.PX4_SITL_HOME
STEP_US = 4000  # 250 Hz
# PX4's expectation at its default home (WMM-2020 grid compiled into PX4)
PX4_HOME_DECLINATION_DEG, PX4_HOME_INCLINATION_DEG, PX4_HOME_STRENGTH_G = 3.41, 63.16, 0.4824
_instances = itertools.count(30)  # PX4 instances >= 30: ports 4590 + k, away from real PX4s


def hover_u(platform=PLATFORM) -> float:
    """Motor output (0..1, rotor speed / w_max) at which four rotors carry the weight."""
    w = math.sqrt(platform.mass_kg * 9.80665 / (4 * platform.thrust_coefficient))
    return w / platform.rotor_speed_max_rad_s


@contextmanager
def bridge_and_peer(ground_truth=False, **kw):
    instance = next(_instances)
    bridge = Px4Bridge(PLATFORM, instance=instance, ground_truth=ground_truth, **kw)
    with bridge:
        peer = Px4Peer(bridge.port, instance=instance, expect_ground_truth=ground_truth)
        with peer:
            yield bridge, peer


def into_lockstep(bridge: Px4Bridge, peer: Px4Peer, n: int = 20, motors=()):
    """Answer frames as PX4 does after its boot (each frame it reads, in order) for at least
    n frames and until the peer holds the newest frame with the bridge in lockstep, i.e.
    the bridge waits for this peer's answer. Boot frames still queued get answered too:
    the bridge ignores answers to frames it has already superseded. Returns the frames."""
    frames_ = [peer.recv_frame()]
    k = 0
    while True:
        s = bridge.stats
        if k >= n and s.lockstep and s.sim_time_us == peer.last_time_usec:
            return frames_
        frames_.append(peer.step(motors))
        k += 1


def sensor_array(frames_, *names):
    return np.array([[getattr(f.sensor, n) for n in names] for f in frames_])


# --- lockstep ---------------------------------------------------------------------------
@pytest.mark.e2e
def test_lockstep_one_frame_per_answer_time_steps_and_pause():
    with bridge_and_peer() as (bridge, peer):
        first = into_lockstep(bridge, peer)
        s0 = bridge.stats
        assert s0.connections == 1 and s0.connected and s0.lockstep
        assert s0.other_messages == 2  # PX4's HEARTBEAT and SET_MESSAGE_INTERVAL
        n = 300
        frames_ = peer.fly([0.0] * 4, n)
        s1 = bridge.stats
        # exactly one HIL_SENSOR and one physics step per actuator message
        assert s1.actuator_messages - s0.actuator_messages == n
        assert s1.sensor_frames - s0.sensor_frames == n
        assert s1.steps - s0.steps == n
        assert s1.boot_frames == s0.boot_frames
        times = np.array([f.time_usec for f in first + frames_])
        assert times[0] > 0
        assert np.all(np.diff(times) == STEP_US)  # strictly increasing by the IMU period
        assert s1.sim_time_us == times[-1]
        # the peer pauses: nothing is sent, simulated time stands still
        assert [m.get_type() for m in peer.quiet(0.5)] == []
        s2 = bridge.stats
        assert s2.sim_time_us == s1.sim_time_us and s2.steps == s1.steps
        assert s2.sensor_frames == s1.sensor_frames
        # answering releases exactly the next frame
        f = peer.step([0.0] * 4)
        assert f.time_usec == times[-1] + STEP_US
        assert [m.get_type() for m in peer.quiet(0.2)] == []
        assert bridge.stats.sensor_frames == s2.sensor_frames + 1
        assert bridge.stats.bad_packets == 0 and bridge.stats.unexpected_messages == 0


@pytest.mark.e2e
def test_boot_frames_flow_before_the_first_answer_with_motors_off():
    with bridge_and_peer() as (bridge, peer):
        boot = [peer.recv_frame() for _ in range(5)]  # PX4 booting: no answers yet
        times = [f.time_usec for f in boot]
        assert np.all(np.diff(times) == STEP_US)
        s = bridge.stats
        assert s.boot_frames >= 5 and s.actuator_messages == 0 and not s.lockstep
        assert np.allclose(bridge.vehicle.position_ned(), 0.0)
        # PX4 booted: it answers each frame it reads (answers to frames the bridge has
        # already superseded are ignored); lockstep starts with the first current one
        answers = 0
        while True:  # until the bridge has taken every answer and waits for this peer's
            s = bridge.stats
            if answers >= 10 and s.lockstep and s.actuator_messages == answers and \
                    s.sim_time_us == peer.last_time_usec:
                break
            peer.step([0.0] * 4, armed=False)
            answers += 1
        assert not s.px4_armed
        # every frame after boot was released by one answer to the newest frame
        assert s.sensor_frames == s.boot_frames + s.actuator_messages - s.stale_actuator_messages


@pytest.mark.e2e
def test_paced_lockstep_and_a_px4_without_lockstep():
    # at a speed factor the frames still go one per answer
    with bridge_and_peer(speed_factor=100.0) as (bridge, peer):
        frames_ = into_lockstep(bridge, peer, n=50)
        assert np.all(np.diff([f.time_usec for f in frames_]) == STEP_US)
        assert [m.get_type() for m in peer.quiet(0.2)] == []
    # a PX4 built without lockstep: the bridge runs on at the wall clock with its outputs
    with bridge_and_peer() as (bridge, peer):
        peer.recv_frame()
        peer.answer([0.2] * 4, lockstep=False)
        frames_ = [peer.recv_frame() for _ in range(10)]  # no answers needed
        assert np.all(np.diff([f.time_usec for f in frames_]) == STEP_US)
        s = bridge.stats
        assert not s.lockstep and s.actuator_messages == 1 and s.px4_armed
        assert np.allclose(bridge.vehicle.motor_commands, 0.2)


# --- sensors ----------------------------------------------------------------------------
@pytest.mark.e2e
def test_sensors_at_rest_match_gravity_atmosphere_field_and_home():
    with bridge_and_peer(ground_truth=True) as (bridge, peer):
        frames_ = into_lockstep(bridge, peer, n=750)  # 3 s on the ground, motors off
    acc = sensor_array(frames_, "xacc", "yacc", "zacc")
    gyr = sensor_array(frames_, "xgyro", "ygyro", "zgyro")
    assert np.allclose(acc.mean(axis=0), [0.0, 0.0, -9.80665], atol=0.1)
    assert np.all((acc.std(axis=0) > 0.01) & (acc.std(axis=0) < 0.1))
    assert np.allclose(gyr.mean(axis=0), 0.0, atol=0.003)
    assert np.all((gyr.std(axis=0) > 0.001) & (gyr.std(axis=0) < 0.01))
    # barometer: the standard atmosphere at 488 m (hPa), within the noise
    p_488_hpa = 1013.25 * (1.0 - 2.25577e-5 * HOME_ALT) ** 5.25588
    baro = sensor_array(frames_, "abs_pressure", "pressure_alt", "temperature")
    assert abs(baro[:, 0].mean() - p_488_hpa) < 0.1
    assert abs(baro[:, 1].mean() - HOME_ALT) < 1.0
    assert abs(baro[:, 2].mean() - (15.0 - 0.0065 * HOME_ALT)) < 0.1
    assert all(f.sensor.fields_updated == 0x1BFF and f.sensor.id == 0 for f in frames_)
    # magnetometer: back into NED with the true attitude, it is PX4's field at home
    mag_ned = []
    for f in frames_:
        w, x, y, z = f.state.attitude_quaternion
        body = [f.sensor.xmag, f.sensor.ymag, f.sensor.zmag]
        mag_ned.append(Rotation.from_quat([x, y, z, w]).apply(body))
    n_, e_, d_ = np.mean(mag_ned, axis=0)
    assert abs(math.degrees(math.atan2(e_, n_)) - PX4_HOME_DECLINATION_DEG) < 0.5
    assert abs(math.degrees(math.atan2(d_, math.hypot(n_, e_))) - PX4_HOME_INCLINATION_DEG) < 0.5
    assert abs(math.sqrt(n_ * n_ + e_ * e_ + d_ * d_) - PX4_HOME_STRENGTH_G) < 0.005
    # the vehicle spawned facing north unless told otherwise: NED yaw 0 in the truth
    w, x, y, z = frames_[-1].state.attitude_quaternion
    assert abs(Rotation.from_quat([x, y, z, w]).as_euler("ZYX", degrees=True)[0]) < 0.1
    # GPS: at home, 3D fix, 10 satellites, 10 Hz (every 25th frame)
    gps = [f.gps for f in frames_ if f.gps is not None]
    assert 29 <= len(gps) <= 31
    assert np.all(np.diff([g.time_usec for g in gps]) == 100_000)
    assert all(g.fix_type == 3 and g.satellites_visible == 10 for g in gps)
    assert all(0 < g.eph < 300 and 0 < g.epv < 500 for g in gps)
    lat = np.array([g.lat for g in gps]) / 1e7
    lon = np.array([g.lon for g in gps]) / 1e7
    alt = np.array([g.alt for g in gps]) / 1e3
    assert np.all(np.abs(lat - HOME_LAT) < 1e-5) and np.all(np.abs(lon - HOME_LON) < 1e-5)
    assert np.all(np.abs(alt - HOME_ALT) < 1.5)
    assert np.all(np.abs([g.vn for g in gps]) < 20) and np.all(np.abs([g.vd for g in gps]) < 25)
    # the ground truth is the truth: at home, at rest
    st = frames_[-1].state
    assert abs(st.lat / 1e7 - HOME_LAT) < 1e-7 and abs(st.lon / 1e7 - HOME_LON) < 1e-7
    assert abs(st.alt / 1e3 - HOME_ALT) < 0.01 and st.vx == st.vy == st.vz == 0
    assert st.zacc == -1000 and st.xacc == 0


@pytest.mark.e2e
def test_the_spawn_heading_is_north_unless_told_otherwise():
    # --spawn-yaw 90: the vehicle PX4 meets faces east, in the truth and in its compass
    with bridge_and_peer(ground_truth=True, spawn_heading_deg=90.0) as (bridge, peer):
        frames_ = into_lockstep(bridge, peer, n=5)
    w, x, y, z = frames_[-1].state.attitude_quaternion
    assert Rotation.from_quat([x, y, z, w]).as_euler("ZYX", degrees=True)[0] == \
        pytest.approx(90.0, abs=0.1)
    f = frames_[-1].sensor  # the field points north-ish: to the vehicle's left
    assert f.ymag < -0.1 and abs(f.xmag) < 0.05
    for heading, says in ((-90.0, "spawn heading 270.0 deg"), (None, "spawn heading 0.0 deg")):
        lines = []
        run_px4_bridge(PLATFORM.name, None, instance=next(_instances), duration_s=0.1,
                       echo=lines.append, spawn_heading_deg=heading)
        assert says in lines[0]


@pytest.mark.e2e
def test_sensor_values_never_repeat_from_frame_to_frame():
    with bridge_and_peer() as (bridge, peer):
        frames_ = into_lockstep(bridge, peer, n=1250)
    fields = ["xacc", "yacc", "zacc", "xgyro", "ygyro", "zgyro", "xmag", "ymag", "zmag",
              "abs_pressure", "pressure_alt", "temperature"]
    values = sensor_array(frames_, *fields)
    assert np.all(np.diff(values, axis=0) != 0.0), "a HIL_SENSOR field repeated exactly"
    gps = [f.gps for f in frames_ if f.gps is not None]
    assert len(gps) >= 49
    for name in ("lat", "lon", "alt", "eph", "epv", "vel", "vn", "ve", "vd", "cog"):
        v = np.array([getattr(g, name) for g in gps])
        assert np.all(np.diff(v) != 0), f"HIL_GPS {name} repeated exactly"


def test_sensor_suite_is_deterministic_and_validates_its_inputs():
    class Still:
        def position_ned(self):
            return np.zeros(3)

        def velocity_ned(self):
            return np.zeros(3)

        def q_ned_frd(self):
            return np.array([1.0, 0.0, 0.0, 0.0])

        def gyro_frd(self):
            return np.zeros(3)

        def accel_frd(self):
            return np.array([0.0, 0.0, -9.80665])

    def readings(seed):
        s = SensorSuite(seed=seed)
        return [(s.hil_sensor(Still(), t), s.gps(Still(), t)) for t in range(4000, 40000, 4000)]

    assert readings(3) == readings(3)
    assert readings(3) != readings(4)
    assert abs(isa_pressure_pa(0.0) - 101325.0) < 1e-9
    assert abs(isa_altitude_m(isa_pressure_pa(488.0)) - 488.0) < 1e-6
    with pytest.raises(ValueError, match="no magnetic field is built in for home"):
        SensorSuite(home=(52.0, 4.0, 0.0))
    SensorSuite(home=(52.0, 4.0, 0.0), mag_field=MagField(2.0, 67.0, 0.49))
    with pytest.raises(ValueError, match="gyro_noise_density"):
        SensorNoise(gyro_noise_density=-1.0)
    with pytest.raises(ValueError, match="inclination_deg"):
        MagField(3.0, 95.0, 0.48)


# --- motors -----------------------------------------------------------------------------
def test_quad_x_maps_px4_motors_one_to_one_and_other_layouts_are_refused():
    bridge = Px4Bridge(PLATFORM, instance=next(_instances))  # opens no socket
    assert bridge.motor_map == (0, 1, 2, 3)  # our quad_x order is PX4's
    plus = dataclasses.replace(PLATFORM, layout="quad_plus")
    with pytest.raises(MotorMappingError, match=r"layout quad_plus.*none_iris motor 1"):
        Px4Bridge(plus, instance=next(_instances))
    # a quad-X listed in another order is re-ordered by geometry, not by index
    pos = bridge.vehicle.motor_positions_flu()[[2, 0, 3, 1]]
    spins = bridge.vehicle.motor_spins()[[2, 0, 3, 1]]
    assert px4_motor_map(pos, spins) == (1, 3, 0, 2)
    # same geometry, wrong spin directions: refused
    with pytest.raises(MotorMappingError, match="same spin"):
        px4_motor_map(bridge.vehicle.motor_positions_flu(), -bridge.vehicle.motor_spins())


@pytest.mark.e2e
@pytest.mark.parametrize("motor, signs", [
    (0, (-1, +1, +1)),  # motor 1 front right: roll left, pitch up, yaw moment +
    (1, (+1, -1, +1)),  # motor 2 rear left: roll right, pitch down, yaw +
    (2, (+1, +1, -1)),  # motor 3 front left: roll right, pitch up, yaw -
    (3, (-1, -1, -1)),  # motor 4 rear right: roll left, pitch down, yaw -
])
def test_one_px4_motor_up_turns_the_vehicle_as_on_none_iris(motor, signs):
    lift = 1.15 * hover_u()
    with bridge_and_peer() as (bridge, peer):
        into_lockstep(bridge, peer, n=5)
        peer.fly([lift] * 4, 100)  # 0.4 s: off the ground, level
        base = sensor_array(peer.fly([lift] * 4, 5), "xgyro", "ygyro", "zgyro").mean(axis=0)
        u = [lift] * 4
        u[motor] += 0.1
        after = sensor_array(peer.fly(u, 10)[-5:], "xgyro", "ygyro", "zgyro").mean(axis=0)
        assert bridge.stats.crash is None
    rate = after - base  # FRD body rates: roll, pitch, yaw
    assert np.all(np.sign(rate) == signs), rate
    assert np.all(np.abs(rate) > 0.02), rate


@pytest.mark.e2e
def test_a_hover_command_holds_altitude():
    """A PX4-like altitude loop on the ground truth: hover thrust plus PD, all four motors."""
    u0, target = hover_u(), 2.0
    with bridge_and_peer(ground_truth=True) as (bridge, peer):
        f = into_lockstep(bridge, peer, n=5)[-1]
        heights, baro_err, gps_err = [], [], []
        for _ in range(1500):  # 6 s
            h = f.state.alt / 1000.0 - HOME_ALT
            v_up = -f.state.vz / 100.0
            acc = 3.0 * (target - h) - 3.0 * v_up
            u = u0 * math.sqrt(min(2.0, max(0.3, 1.0 + acc / 9.80665)))
            f = peer.step([u] * 4)
            heights.append(f.state.alt / 1000.0 - HOME_ALT)
            baro_err.append(f.sensor.pressure_alt - f.state.alt / 1000.0)
            if f.gps is not None:
                gps_err.append(f.gps.alt / 1000.0 - f.state.alt / 1000.0)
    last = np.array(heights[-500:])
    assert np.all(np.abs(last - target) < 0.15), (last.min(), last.max())
    assert abs(np.mean(baro_err)) < 0.5 and abs(np.mean(gps_err)) < 1.0
    w, x, y, z = f.state.attitude_quaternion
    roll, pitch = Rotation.from_quat([x, y, z, w]).as_euler("ZYX", degrees=True)[2:0:-1]
    assert abs(roll) < 1.0 and abs(pitch) < 1.0


# --- connections ------------------------------------------------------------------------
@pytest.mark.e2e
def test_disconnect_then_reconnect_resets_the_vehicle_and_time_runs_on():
    instance = next(_instances)
    with Px4Bridge(PLATFORM, instance=instance, ground_truth=True) as bridge:
        with Px4Peer(bridge.port, instance=instance, expect_ground_truth=True) as peer:
            into_lockstep(bridge, peer, n=5)
            last = peer.fly([0.6] * 4, 250)[-1]  # 1 s climbing
            assert last.state.alt / 1000.0 - HOME_ALT > 1.0
        # PX4 restarts: a new connection
        with Px4Peer(bridge.port, instance=instance, expect_ground_truth=True) as peer2:
            f = peer2.recv_frame()
            assert f.time_usec > last.time_usec  # one clock over the bridge's life
            assert abs(f.state.alt / 1000.0 - HOME_ALT) < 0.01
            assert f.state.vz == 0 and f.state.vx == 0
            assert f.gps is not None and abs(f.gps.alt / 1000.0 - HOME_ALT) < 1.5
            assert abs(f.sensor.pressure_alt - HOME_ALT) < 1.0
            more = into_lockstep(bridge, peer2, n=5)
            assert np.all(np.diff([g.time_usec for g in [f] + more]) == STEP_US)
            s = bridge.stats
            assert s.connections == 2 and s.connected and s.lockstep
        # a PX4 that connects while another is still connected takes over
        with Px4Peer(bridge.port, instance=instance, expect_ground_truth=True) as old:
            into_lockstep(bridge, old, n=3)
            old.fly([0.6] * 4, 100)
            with Px4Peer(bridge.port, instance=instance, expect_ground_truth=True) as new:
                f = new.recv_frame()
                assert abs(f.state.alt / 1000.0 - HOME_ALT) < 0.01
                into_lockstep(bridge, new, n=3)
                with pytest.raises(ConnectionError):
                    old.quiet(1.0)
                    old.recv_frame(limit_s=1.0)
            assert bridge.stats.connections == 4


@pytest.mark.e2e
def test_malformed_and_unexpected_input_is_counted_not_fatal():
    with bridge_and_peer() as (bridge, peer):
        f = into_lockstep(bridge, peer, n=5)[-1]
        s0 = bridge.stats
        enc = mav.MAVLink(None, 1, 1)
        good = mav.MAVLink_hil_actuator_controls_message(
            f.time_usec, [0.3] * 16, 129, 1).pack(enc)
        corrupt = bytearray(good)
        corrupt[20] ^= 0xFF  # a flipped payload byte: bad checksum
        peer.send_raw(b"GET / HTTP/1.1\r\nHost: px4\r\n\r\n")
        peer.send_raw(bytes(corrupt))
        peer.send(mav.MAVLink_hil_sensor_message(f.time_usec, *[0.0] * 13, 0x1FFF, 0))
        # none of it answered the frame: the bridge still waits
        assert [m.get_type() for m in peer.quiet(0.3)] == []
        s = bridge.stats
        assert s.bad_packets >= 2 and s.unexpected_messages == 1
        assert s.actuator_messages == s0.actuator_messages and s.steps == s0.steps
        # non-finite outputs count as bad and run the motor as 0; the frame is answered
        n_bad = s.bad_packets
        peer.answer([float("nan"), 0.0, 0.0, 0.0])
        f2 = peer.recv_frame()
        assert f2.time_usec == f.time_usec + STEP_US
        assert bridge.stats.bad_packets == n_bad + 1
        # and lockstep carries on
        frames_ = peer.fly([0.0] * 4, 10)
        assert np.all(np.diff([f2.time_usec] + [g.time_usec for g in frames_]) == STEP_US)
        assert bridge.running and bridge.stats.connections == 1


@pytest.mark.e2e
def test_clients_that_vanish_or_talk_nonsense_do_not_stop_the_bridge():
    import socket

    with bridge_and_peer() as (bridge, peer):
        into_lockstep(bridge, peer, n=3)
        peer.close()
        for payload in (b"", b"\x00\xff" * 500 + b"not mavlink at all"):
            with socket.create_connection(("127.0.0.1", bridge.port)) as s:
                if payload:
                    s.sendall(payload)
        again = Px4Peer(bridge.port)
        with again:
            frames_ = into_lockstep(bridge, again, n=3)
            assert np.all(np.diff([f.time_usec for f in frames_]) == STEP_US)
        s = bridge.stats
        assert s.connections == 4 and bridge.running


# --- scenario ---------------------------------------------------------------------------
def roof_scenario() -> Scenario:
    """A 4 x 4 m slab whose underside is 1.5 m above the takeoff point."""
    roof = trimesh.creation.box(extents=[4.0, 4.0, 0.5])
    roof.apply_translation([0.0, 0.0, 1.75])
    return Scenario(family="roof", index=1, seed=0, category="user", mesh=roof,
                    bounds_min=[-10.0, -10.0, 0.0], bounds_max=[10.0, 10.0, 8.0],
                    takeoff=[0.0, 0.0, 0.0], start=[0.0, 0.0, 1.0], start_yaw=0.0,
                    goal=[8.0, 0.0, 1.0], piece_first_face=[0], piece_names=["roof"])


@pytest.mark.e2e
def test_a_collision_crashes_the_vehicle_and_px4_cannot_restart_the_motors():
    instance = next(_instances)
    with Px4Bridge(PLATFORM, scenario=roof_scenario(), instance=instance,
                   ground_truth=True) as bridge:
        with Px4Peer(bridge.port, instance=instance, expect_ground_truth=True) as peer:
            into_lockstep(bridge, peer, n=5)
            for _ in range(500):  # full throttle into the roof
                peer.step([1.0] * 4)
                if bridge.stats.crash is not None:
                    break
            crash = bridge.stats.crash
            assert crash is not None and crash.what == "roof" and crash.speed_m_s > 0.5
            # PX4 keeps commanding full throttle: the vehicle falls back and stays down
            fall = peer.fly([1.0] * 4, 500)
            min_acc = min(-g.sensor.zacc for g in fall[:50])
            assert min_acc < 3.0  # free fall: the accelerometer reads far less than 1 g
            rest = fall[-50:]
            assert all(abs(g.state.alt / 1000.0 - HOME_ALT) < 0.05 for g in rest)
            assert abs(np.mean([g.sensor.zacc for g in rest]) + 9.80665) < 0.1
            assert abs(np.mean([g.sensor.pressure_alt for g in rest]) - HOME_ALT) < 1.0
            assert np.all(bridge.vehicle.motor_commands == 1.0)  # commanded, not flown
        # a new PX4 connection resets the crash
        with Px4Peer(bridge.port, instance=instance, expect_ground_truth=True) as peer2:
            into_lockstep(bridge, peer2, n=5)
            assert bridge.stats.crash is None and bridge.vehicle.crash is None


# --- configuration ----------------------------------------------------------------------
def test_bad_configuration_is_refused_with_a_clear_message():
    with pytest.raises(ValueError, match="instance"):
        Px4Bridge(PLATFORM, instance=-1)
    with pytest.raises(ValueError, match="speed_factor"):
        Px4Bridge(PLATFORM, speed_factor=0.0)
    with pytest.raises(ValueError, match="imu_rate_hz"):
        Px4Bridge(PLATFORM, imu_rate_hz=300)
    with pytest.raises(ValueError, match="physics steps"):
        Px4Bridge(PLATFORM, imu_rate_hz=2000)
    with pytest.raises(ValueError, match="FAMILY:INDEX"):
        scenario_from_spec("forest")
    with pytest.raises(ValueError, match="integers"):
        scenario_from_spec("forest:x")
    assert scenario_from_spec(None) is None


def test_px4_parameters_describe_our_geometry_and_thrust_model():
    p = px4_parameters(PLATFORM)
    c = PLATFORM.arm_length_m * math.sqrt(0.5)
    # PX4 motor 1 front right, 2 rear left, 3 front left, 4 rear right (FRD), KM > 0 = CCW
    for i, (sx, sy, spin) in enumerate([(1, 1, 1), (-1, -1, 1), (1, -1, -1), (-1, 1, -1)]):
        assert p[f"CA_ROTOR{i}_PX"] == pytest.approx(sx * c, abs=1e-4)
        assert p[f"CA_ROTOR{i}_PY"] == pytest.approx(sy * c, abs=1e-4)
        assert p[f"CA_ROTOR{i}_KM"] == pytest.approx(spin * PLATFORM.torque_thrust_ratio_m,
                                                     abs=1e-4)
    assert p["THR_MDL_FAC"] == 1.0
    assert p["MPC_THR_HOVER"] == pytest.approx(hover_u() ** 2, abs=1e-3)
    assert hover_output(PLATFORM) == pytest.approx(hover_u())


@pytest.mark.e2e
def test_run_px4_bridge_serves_prints_and_returns_its_counters():
    lines = []
    instance = next(_instances)
    stats = run_px4_bridge(PLATFORM.name, None, instance=instance, duration_s=0.3,
                           echo=lines.append)
    text = "\n".join(lines)
    assert f"127.0.0.1:{4560 + instance}" in text and "PX4_SIM_MODEL=none_iris" in text
    assert f"-i {instance}" in text and "PX4_PARAM_MPC_THR_HOVER=" in text
    assert "stopped" in lines[-1] and stats.connections == 0
    with pytest.raises(ValueError, match="unknown platform"):
        run_px4_bridge("no such platform", None, instance=instance, echo=lines.append)
    with pytest.raises(ValueError, match="FAMILY:INDEX"):
        run_px4_bridge(PLATFORM.name, "forest", instance=instance, echo=lines.append)
