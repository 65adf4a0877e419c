"""Payload codecs: round trips, and a BusPayloadError naming the problem for every kind of
malformed input."""

import json
import math
import re
import struct

import numpy as np
import pytest

from ft_sitl.bus.codec import (
    HEADER_SIZE,
    BusPayloadError,
    Event,
    MoverState,
    MoverStates,
    Status,
    Telemetry,
    decode_config,
    decode_event,
    decode_frame,
    decode_movers,
    decode_status,
    decode_telemetry,
    encode_config,
    encode_depth,
    encode_event,
    encode_movers,
    encode_points,
    encode_status,
    encode_telemetry,
    validate_config,
)
from ft_sitl.rotations import matrix_from_quat, quat_from_matrix


def sample_telemetry(**overrides) -> Telemetry:
    args = dict(time_usec=12_345_678, p_world_m=(1.25, -3.5, 10.123456789),
                v_world_m_s=np.array([0.1, 0.2, -0.3]),
                q_world_body=(math.cos(0.3), 0.0, 0.0, math.sin(0.3)),
                w_body_rad_s=[0.01, -0.02, 0.5], motors=(0.51, 0.52, 0.49, 0.5))
    args.update(overrides)
    return Telemetry(**args)


def telemetry_obj(**overrides) -> dict:
    obj = json.loads(encode_telemetry(sample_telemetry()))
    obj.update(overrides)
    return obj


def dumps(obj) -> bytes:
    return json.dumps(obj).encode()


# --- telemetry ----------------------------------------------------------------------------------
def test_telemetry_round_trip():
    s = sample_telemetry()
    payload = encode_telemetry(s)
    assert b" " not in payload  # compact
    obj = json.loads(payload)
    assert obj["v"] == 1 and obj["time_usec"] == 12_345_678 and obj["t"] == 12.345678
    assert set(obj) == {"v", "t", "time_usec", "p_world_m", "v_world_m_s", "q_world_body",
                        "w_body_rad_s", "motors"}  # (calm air: no wind field)
    back = decode_telemetry(payload)
    assert back.time_usec == s.time_usec and back.t == pytest.approx(12.345678)
    for name, tol in (("p_world_m", 5e-7), ("v_world_m_s", 5e-7), ("q_world_body", 5e-10),
                      ("w_body_rad_s", 5e-7), ("motors", 5e-5)):
        np.testing.assert_allclose(getattr(back, name), getattr(s, name), rtol=0, atol=tol)
    assert decode_telemetry(payload.decode()) == back  # str payloads too
    # the wind is optional: a payload without it is calm air; with it, it round-trips
    assert back.wind_world_m_s == (0.0, 0.0, 0.0)
    windy = decode_telemetry(dumps({**obj, "wind_world_m_s": [6.0, -1.5, 0.25]}))
    assert windy.wind_world_m_s == (6.0, -1.5, 0.25)
    again = json.loads(encode_telemetry(windy))
    assert again["wind_world_m_s"] == [6.0, -1.5, 0.25]


@pytest.mark.parametrize("overrides, message", [
    ({"time_usec": -1}, r"Expected `int` >= 0 - at `\$.time_usec`, got -1"),
    ({"time_usec": 2**63}, r"Expected `int` <= 9223372036854775807 - at `\$.time_usec`"),
    ({"time_usec": 1.5}, r"Expected `int`, got `float` - at `\$.time_usec`"),
    ({"time_usec": True}, r"Expected `int`, got `bool` - at `\$.time_usec`"),
    ({"time_usec": np.int64(5)}, None),
    ({"p_world_m": (0.0, 0.0)}, r"Expected `array` of length 3, got 2 - at `\$.p_world_m`"),
    ({"v_world_m_s": (0.0, math.nan, 0.0)}, r"v_world_m_s\[1\] must be finite"),
    ({"w_body_rad_s": (0.0, "x", 0.0)}, r"Expected `float`, got `str` - at "
                                        r"`\$.w_body_rad_s\[1\]`"),
    ({"q_world_body": (1.0, 0.1, 0.0, 0.0)}, "q_world_body must be a unit quaternion"),
    ({"motors": ()}, r"Expected `array` of length >= 1 - at `\$.motors`, got \[\]"),
    ({"motors": (0.5,) * 17}, r"Expected `array` of length <= 16 - at `\$.motors`"),
    ({"motors": (0.5, 1.2)}, r"Expected `float` <= 1.0 - at `\$.motors\[1\]`, got 1.2"),
    ({"motors": (-0.1,)}, r"Expected `float` >= 0.0 - at `\$.motors\[0\]`, got -0.1"),
    ({"p_world_m": np.zeros((3, 1))}, "p_world_m must be one-dimensional"),
])
def test_telemetry_rejects_bad_values(overrides, message):
    if message is None:  # accepted (numpy integers are integers)
        sample_telemetry(**overrides)
        return
    with pytest.raises(BusPayloadError, match=message) as info:
        sample_telemetry(**overrides)
    assert str(info.value).startswith("telemetry: ")


@pytest.mark.parametrize("payload, message", [
    (b"{not json", "not valid JSON"),
    (b"\xff\xfe{}", "not UTF-8"),
    (b"[1, 2]", "Expected `object`, got `array`"),
    (b"42", "Expected `object`, got `int`"),
    (dumps({k: v for k, v in telemetry_obj().items() if k != "v"}),
     "Object missing required field `v`"),
    (dumps(telemetry_obj(v=2)), "unsupported schema version v=2"),
    (dumps(telemetry_obj(v="1")), r"Expected `int`, got `str` - at `\$.v`"),
    (dumps({k: v for k, v in telemetry_obj().items() if k != "motors"}),
     "Object missing required field `motors`"),
    (dumps(telemetry_obj(extra=1)), "Object contains unknown field `extra`"),
    (dumps(telemetry_obj(t=99.0)), "t = 99.0 s disagrees with time_usec = 12345678"),
    (dumps(telemetry_obj(time_usec=12345678.0)), r"Expected `int`, got `float` - at "
                                                 r"`\$.time_usec`"),
    (dumps(telemetry_obj(p_world_m="1,2,3")), r"Expected `array`, got `str` - at "
                                              r"`\$.p_world_m`"),
    (dumps(telemetry_obj(p_world_m=[1, 2, True])), r"Expected `float`, got `bool` - at "
                                                   r"`\$.p_world_m\[2\]`"),
    (dumps(telemetry_obj(motors=[0.5, 2.0])), r"Expected `float` <= 1.0 - at "
                                              r"`\$.motors\[1\]`, got 2.0"),
    (dumps(telemetry_obj(q_world_body=[0, 0, 0, 0])), "unit quaternion"),
    (encode_telemetry(sample_telemetry()).replace(b'"p_world_m":[1.25',
                                                  b'"p_world_m":[NaN'),
     "JSON constant NaN is not allowed"),
    (encode_telemetry(sample_telemetry()).replace(b'"p_world_m":[1.25',
                                                  b'"p_world_m":[Infinity'),
     "JSON constant Infinity is not allowed"),
    (b'{"v":1,"pad":"' + b"x" * 70000 + b'"}', "more than the 65536 allowed"),
    (12, "payload must be bytes or str, got int"),
])
def test_telemetry_decoder_rejects(payload, message):
    with pytest.raises(BusPayloadError, match=message) as info:
        decode_telemetry(payload)
    assert str(info.value).startswith("telemetry: ")


# --- events -------------------------------------------------------------------------------------
@pytest.mark.parametrize("event", [
    Event("armed", 1_000_000),
    Event("disarmed", 2_000_000),
    Event("mode", 1_500_000, {"mode": "OFFBOARD"}),
    Event("collision", 7_250_000, {"object": "tree_3", "speed_m_s": 2.5}),
    Event("trial_start", 0, {"trial_id": "a1b2", "scenario": "forest/3"}),
    Event("trial_end", 60_000_000, {"outcome": "success", "path_m": 41.2, "ok": True,
                                    "goal": [5.0, 18.0, 1.5], "note": None}),
    Event("battery_low", 30_000_001, {"remaining": 0.15}),
    Event("geofence", 12_000_000, {"reason": "outside the fence", "action": "return"}),
])
def test_event_round_trip(event):
    payload = encode_event(event)
    obj = json.loads(payload)
    assert obj["v"] == 1 and obj["type"] == event.type and obj["t"] == event.t
    assert obj["time_usec"] == event.time_usec
    assert decode_event(payload) == event


def test_event_normalises_numpy_values():
    e = Event("collision", 5, {"object": "wall", "speed_m_s": np.float32(1.5),
                               "n": np.int64(3), "flag": np.bool_(True),
                               "at": np.array([1.0, 2.0, 3.0])})
    assert e.fields == {"object": "wall", "speed_m_s": 1.5, "n": 3, "flag": True,
                        "at": [1.0, 2.0, 3.0]}
    assert decode_event(encode_event(e)) == e


@pytest.mark.parametrize("args, message", [
    (("Collision", 0, {}), r"type must match \[a-z\]"),
    (("", 0, {}), "type must match"),
    (("collision", 0, {"speed_m_s": 1.0}), "missing required field `object`"),
    (("collision", 0, {"object": "x", "speed_m_s": -1.0}),
     r"Expected `float` >= 0.0 - at `\$.speed_m_s`, got -1.0"),
    (("collision", 0, {"object": "x", "speed_m_s": "fast"}),
     r"Expected `float`, got `str` - at `\$.speed_m_s`"),
    (("mode", 0, {"mode": ""}), r"Expected `str` of length >= 1 - at `\$.mode`"),
    (("trial_end", 0, {}), "missing required field `outcome`"),
    (("geofence", 0, {"reason": "outside the fence"}), "missing required field `action`"),
    (("armed", -5, {}), r"time_usec must be in \[0"),
    (("armed", 0, {"t": 1.0}), "field name 't' is reserved"),
    (("armed", 0, {"Bad-Name": 1}), "field name 'Bad-Name' must match"),
    (("armed", 0, {"x": {"nested": 1}}),
     r"field 'x': Expected `bool \| int \| float \| str \| array \| null`, got `object`"),
    (("armed", 0, {"x": math.inf}), r"field 'x'\[0\] must be finite, got inf"),
    (("armed", 0, {"x": [1.0, math.nan]}), r"field 'x'\[1\] must be finite, got nan"),
    (("armed", 0, {"x": ["a"]}), r"field 'x': Expected `float`, got `str` - at `\$\[0\]`"),
    (("armed", 0, {"x": "y" * 1025}), "field 'x': Expected `str` of length <= 1024"),
    (("armed", 0, {"x": [0.0] * 65}), "field 'x': Expected `array` of length <= 64"),
    (("armed", 0, {f"f{i}": i for i in range(33)}), "33 fields, more than 32"),
])
def test_event_rejects_bad_values(args, message):
    with pytest.raises(BusPayloadError, match=message):
        Event(*args)


@pytest.mark.parametrize("obj, message", [
    ({"v": 1, "t": 1.0, "time_usec": 1_000_000}, "missing required field `type`"),
    ({"v": 1, "type": "armed", "time_usec": 1_000_000}, "missing required field `t`"),
    ({"type": "armed", "t": 1.0, "time_usec": 1_000_000}, "missing required field `v`"),
    ({"v": 3, "type": "armed", "t": 1.0, "time_usec": 1_000_000}, "unsupported schema "
                                                                   "version v=3"),
    ({"v": 1, "type": 7, "t": 1.0, "time_usec": 1_000_000},
     r"Expected `str`, got `int` - at `\$.type`"),
    ({"v": 1, "type": "Bad-Kind", "t": 1.0, "time_usec": 1_000_000},
     r"Expected `str` matching regex .* - at `\$.type`, got 'Bad-Kind'"),
    ({"v": 1, "type": "armed", "t": 2.0, "time_usec": 1_000_000}, "disagrees with time_usec"),
    ({"v": 1, "type": "armed", "t": 1.0, "time_usec": "1000000"},
     r"Expected `int`, got `str` - at `\$.time_usec`"),
    ({"v": 1, "type": "collision", "t": 1.0, "time_usec": 1_000_000, "object": "w",
      "speed_m_s": -2}, r"Expected `float` >= 0.0 - at `\$.speed_m_s`, got -2"),
    ({"v": 1, "type": "armed", "t": 1.0, "time_usec": 1_000_000, "x": {"a": 1}},
     "field 'x': Expected .*, got `object`"),
])
def test_event_decoder_rejects(obj, message):
    with pytest.raises(BusPayloadError, match=message):
        decode_event(dumps(obj))


def test_event_decoder_rejects_bad_json():
    with pytest.raises(BusPayloadError, match="event: payload is not valid JSON"):
        decode_event(b'{"v":1,')


# --- status and config --------------------------------------------------------------------------
def test_status_round_trip():
    for status in (Status("0", True), Status("0", False, "closed"),
                   Status("uav-7", False, "connection lost")):
        assert decode_status(encode_status(status)) == status
    assert json.loads(encode_status(Status("3", True))) == {"v": 1, "vehicle": "3",
                                                           "status": "online"}


@pytest.mark.parametrize("obj, message", [
    ({"v": 1, "vehicle": "0", "status": "sleeping"},
     r"Invalid enum value 'sleeping' - at `\$.status`"),
    ({"v": 1, "vehicle": "a/b", "status": "online"}, "vehicle must be 1 to 64 characters"),
    ({"v": 1, "status": "online"}, "missing required field `vehicle`"),
    ({"v": 1, "vehicle": "0", "status": "online", "x": 1}, "unknown field `x`"),
    ({"v": 1, "vehicle": "0", "status": "offline", "reason": 5},
     r"Expected `str \| null`, got `int` - at `\$.reason`"),
    ({"v": 1, "vehicle": "0", "status": "offline", "reason": ""},
     r"Expected `str` of length >= 1 - at `\$.reason`"),
    ({"v": 2, "vehicle": "0", "status": "online"}, "unsupported schema version v=2"),
])
def test_status_decoder_rejects(obj, message):
    with pytest.raises(BusPayloadError, match=message):
        decode_status(dumps(obj))


def test_config_accepts_subsets():
    assert decode_config(b'{"telemetry_rate_hz": 20, "depth": true, "points": false}') == {
        "telemetry_rate_hz": 20.0, "depth": True, "points": False}
    assert decode_config(b'{"v": 1, "depth": false}') == {"depth": False}
    assert decode_config(b'{"telemetry_rate_hz": 0}') == {"telemetry_rate_hz": 0.0}
    assert json.loads(encode_config({"depth": True})) == {"v": 1, "depth": True}


@pytest.mark.parametrize("payload, message", [
    (b"{oops", "config: payload is not valid JSON"),
    (b'"depth"', "Expected `object`, got `str`"),
    (b"{}", "names no setting"),
    (b'{"v": 1}', "names no setting"),
    (b'{"v": 2, "depth": true}', "unsupported schema version v=2"),
    (b'{"depth": "yes"}', r"Expected `bool`, got `str` - at `\$.depth`"),
    (b'{"points": 1}', r"Expected `bool`, got `int` - at `\$.points`"),
    (b'{"telemetry_rate_hz": "20"}', r"Expected `float`, got `str` - at `\$.telemetry_rate_hz`"),
    (b'{"telemetry_rate_hz": true}', r"Expected `float`, got `bool` - at "
                                     r"`\$.telemetry_rate_hz`"),
    (b'{"telemetry_rate_hz": -1}', r"Expected `float` >= 0.0 - at `\$.telemetry_rate_hz`, "
                                   "got -1"),
    (b'{"telemetry_rate_hz": 5000}', r"Expected `float` <= 1000.0 - at "
                                     r"`\$.telemetry_rate_hz`, got 5000"),
    (b'{"telemetry_rate_hz": 1e999}', r"Number out of range - at `\$.telemetry_rate_hz`"),
    (b'{"depth": true, "video": true}', "unknown field `video`"),
])
def test_config_decoder_rejects(payload, message):
    with pytest.raises(BusPayloadError, match=message):
        decode_config(payload)


def test_validate_config_rejects_non_mapping():
    with pytest.raises(BusPayloadError, match="must be a JSON object / mapping"):
        validate_config([("depth", True)])


# --- binary frames ------------------------------------------------------------------------------
def test_depth_frame_round_trip(depth_sample):
    frame, config = depth_sample
    payload = encode_depth(frame, config)
    assert len(payload) == HEADER_SIZE + 160 * 120 * 2 == 192 + 38400
    assert payload[:4] == b"FTSF"
    msg = decode_frame(payload)
    assert (msg.kind, msg.frame, msg.width, msg.height) == ("depth", "optical", 160, 120)
    assert msg.time_usec == frame.t_us and msg.t == pytest.approx(12.345678)
    assert (msg.fx, msg.fy, msg.cx, msg.cy) == (config.fx, config.fy, config.cx, config.cy)
    assert (msg.min_range_m, msg.max_range_m) == (config.min_range_m, config.max_range_m)

    back = msg.to_depth_frame()
    assert back.t_us == frame.t_us
    assert back.depth.shape == frame.depth.shape and back.depth.dtype == np.float32
    np.testing.assert_array_equal(np.isnan(back.depth), np.isnan(frame.depth))
    valid = np.isfinite(frame.depth)
    np.testing.assert_allclose(back.depth[valid], frame.depth[valid], rtol=0, atol=5.01e-4)
    np.testing.assert_array_equal(back.pixels, frame.pixels)
    # a point is its pixel's ray times the depth: the error scales with the ray length
    np.testing.assert_allclose(back.points_world, frame.points_world, rtol=0, atol=1e-3)
    np.testing.assert_allclose(back.points_body, frame.points_body, rtol=0, atol=1e-3)
    np.testing.assert_allclose(back.p_world_body, frame.p_world_body, atol=1e-12)
    np.testing.assert_allclose(back.q_world_body, frame.q_world_body, atol=1e-12)
    np.testing.assert_allclose(back.p_world_camera, frame.p_world_camera, atol=1e-12)
    np.testing.assert_allclose(back.r_world_optical, frame.r_world_optical, atol=1e-12)


def test_depth_zero_means_no_return(depth_sample):
    frame, config = depth_sample
    msg = decode_frame(encode_depth(frame, config))
    np.testing.assert_array_equal(msg.depth_mm == 0, np.isnan(frame.depth))
    assert msg.depth_mm.dtype == np.uint16


@pytest.mark.parametrize("frame_id, attr", [("world", "points_world"),
                                            ("body", "points_body")])
def test_points_round_trip(depth_sample, frame_id, attr):
    frame, config = depth_sample
    payload = encode_points(frame, config, frame_id)
    n = len(frame.points_world)
    assert len(payload) == HEADER_SIZE + n * 12
    msg = decode_frame(payload, expect_kind="points")
    assert (msg.kind, msg.frame, msg.width, msg.height) == ("points", frame_id, n, 1)
    assert msg.points.dtype == np.float32 and msg.points.shape == (n, 3)
    np.testing.assert_allclose(msg.points, getattr(frame, attr), rtol=1e-6, atol=1e-5)


def test_empty_point_cloud(depth_sample):
    frame, config = depth_sample
    from dataclasses import replace

    empty = replace(frame, points_world=np.zeros((0, 3)))
    msg = decode_frame(encode_points(empty, config))
    assert msg.points.shape == (0, 3)


def test_encode_depth_rejects(depth_sample):
    from dataclasses import replace

    frame, config = depth_sample
    with pytest.raises(BusPayloadError, match=r"depth image has shape \(120, 160\), the "
                                              r"camera config says .* \(240, 320\)"):
        encode_depth(frame, replace(config, width=320, height=240, cx=None, cy=None))
    with pytest.raises(BusPayloadError, match="max_range_m = 100.0 m exceeds 65.535 m"):
        encode_depth(frame, replace(config, max_range_m=100.0))
    neg = frame.depth.copy()
    neg[0, 0] = -1.0
    with pytest.raises(BusPayloadError, match="depth has negative values"):
        encode_depth(replace(frame, depth=neg), config)
    with pytest.raises(BusPayloadError, match="r_world_optical is not a rotation matrix"):
        encode_depth(replace(frame, r_world_optical=2 * np.eye(3)), config)
    with pytest.raises(BusPayloadError, match="frame_id must be 'world' or 'body'"):
        encode_points(frame, config, "camera")
    bad = frame.points_world.copy()
    bad[0, 0] = np.nan
    with pytest.raises(BusPayloadError, match="points contain non-finite values"):
        encode_points(replace(frame, points_world=bad), config)


# offsets in the header (see codec._HEADER)
OFF_VERSION, OFF_KIND, OFF_FRAME, OFF_RESERVED = 4, 5, 6, 7
OFF_WIDTH, OFF_HEIGHT, OFF_TIME, OFF_T = 8, 12, 16, 24
OFF_Q_OPTICAL, OFF_FX, OFF_CX, OFF_MAX_RANGE, OFF_Q_BODY = 56, 88, 104, 128, 160


def patched(payload: bytes, offset: int, fmt: str, value) -> bytes:
    buf = bytearray(payload)
    struct.pack_into("<" + fmt, buf, offset, value)
    return bytes(buf)


@pytest.fixture(scope="module")
def depth_payload(depth_sample):
    return encode_depth(*depth_sample)


@pytest.fixture(scope="module")
def points_payload(depth_sample):
    return encode_points(*depth_sample)


@pytest.mark.parametrize("mutate, message", [
    (lambda p: b"XXXX" + p[4:], r"wrong magic b'XXXX' \(expected b'FTSF'\)"),
    (lambda p: patched(p, OFF_VERSION, "B", 2), "unsupported layout version 2"),
    (lambda p: patched(p, OFF_KIND, "B", 9), r"unknown kind 9 \(1 = depth, 2 = points\)"),
    (lambda p: patched(p, OFF_FRAME, "B", 1), "frame code 1 is not valid for depth"),
    (lambda p: patched(p, OFF_RESERVED, "B", 1), "reserved byte 7 must be 0"),
    (lambda p: p[:100], "truncated: 100 bytes, the header alone is 192"),
    (lambda p: b"", "truncated: 0 bytes"),
    (lambda p: p[:-2], r"truncated: 38398 bytes of depth after the header, 160 x 120 x 2 = "
                       "38400 expected"),
    (lambda p: p + b"\0\0", "size mismatch: 38402 bytes of depth"),
    (lambda p: patched(p, OFF_WIDTH, "I", 161), "truncated: 38400 bytes of depth"),
    (lambda p: patched(p, OFF_HEIGHT, "I", 0), r"width and height must be in \[1, 16384\]"),
    (lambda p: patched(p, OFF_WIDTH, "I", 20000), r"width and height must be in \[1, 16384\]"),
    (lambda p: patched(p, OFF_T, "d", 99.0), "t = 99.0 s disagrees with time_usec"),
    (lambda p: patched(p, OFF_TIME, "Q", 2**63), "time_usec 9223372036854775808 exceeds"),
    (lambda p: patched(p, OFF_Q_OPTICAL, "d", 0.9), "q_world_optical is not a unit quaternion"),
    (lambda p: patched(p, OFF_Q_BODY, "d", 5.0), "q_world_body is not a unit quaternion"),
    (lambda p: patched(p, OFF_FX, "d", math.nan), "fx/fy/cx/cy contains non-finite values"),
    (lambda p: patched(p, OFF_FX, "d", -1.0), "fx and fy must be > 0"),
    (lambda p: patched(p, OFF_CX, "d", 500.0), "principal point .* lies outside the 160 x "
                                               "120 image"),
    (lambda p: patched(p, OFF_MAX_RANGE, "d", 0.1), "0 <= min_range_m < max_range_m"),
    (lambda p: patched(p, OFF_MAX_RANGE, "d", 80.0), "max_range_m 80.0 exceeds 65.535"),
    (lambda p: patched(p, OFF_MAX_RANGE, "d", 1.0), r"depth value \d+ mm beyond max_range_m "
                                                    "1.0 m"),
    (lambda p: p[:HEADER_SIZE] + struct.pack("<H", 100) + p[HEADER_SIZE + 2:],
     "depth value 100 mm below min_range_m 0.2 m"),
])
def test_depth_decoder_rejects(depth_payload, mutate, message):
    with pytest.raises(BusPayloadError, match=message):
        decode_frame(mutate(depth_payload))


@pytest.mark.parametrize("mutate, message", [
    (lambda p: patched(p, OFF_FRAME, "B", 0), "frame code 0 is not valid for points"),
    (lambda p: patched(p, OFF_HEIGHT, "I", 2), "height must be 1 for a point cloud"),
    (lambda p: p[:-4], "truncated: .* bytes of points after the header"),
    (lambda p: p + b"\0" * 12, "size mismatch: .* bytes of points after the header"),
    (lambda p: p[:HEADER_SIZE] + struct.pack("<f", math.inf) + p[HEADER_SIZE + 4:],
     "points contain non-finite values"),
])
def test_points_decoder_rejects(points_payload, mutate, message):
    with pytest.raises(BusPayloadError, match=message):
        decode_frame(mutate(points_payload))


def test_decoder_checks_expected_kind(depth_payload, points_payload):
    with pytest.raises(BusPayloadError, match="expected a points frame on this topic"):
        decode_frame(depth_payload, expect_kind="points")
    with pytest.raises(BusPayloadError, match="expected a depth frame on this topic"):
        decode_frame(points_payload, expect_kind="depth")
    with pytest.raises(BusPayloadError, match="payload must be bytes, got str"):
        decode_frame("FTSF")


def test_points_frame_has_no_depth(points_payload):
    msg = decode_frame(points_payload)
    with pytest.raises(ValueError, match="a points frame has no depth image"):
        _ = msg.depth_m
    with pytest.raises(ValueError, match="needs a depth frame"):
        msg.to_depth_frame()


def test_quaternion_matrix_conversions_agree():
    rng = np.random.default_rng(7)
    for _ in range(200):
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        q = -q if q[0] < 0 else q
        r = matrix_from_quat(q)
        np.testing.assert_allclose(quat_from_matrix(r), q, atol=1e-12)


# --- movers -----------------------------------------------------------------------------------
def sample_movers() -> MoverStates:
    return MoverStates(2_500_000, [
        {"name": "person 1", "shape": "person", "p_world_m": (10.123456789, 9.0, 0.9),
         "heading_rad": math.pi, "v_world_m_s": (-1.5, 0.0, 0.0), "radius_m": 0.35,
         "height_m": 1.8},
        MoverState(name="box 1", shape="box", p_world_m=(3.0, 4.0, 0.8), heading_rad=0.5,
                   v_world_m_s=(0.0, 2.0, 0.0), length_m=3.0, width_m=1.5, height_m=1.6),
        {"name": "ball 1", "shape": "sphere", "p_world_m": np.array([1.0, 2.0, 2.5]),
         "heading_rad": np.float64(-0.25), "v_world_m_s": np.zeros(3), "radius_m": 0.4},
    ])


def test_movers_round_trip():
    s = sample_movers()
    back = decode_movers(encode_movers(s))
    assert back.time_usec == 2_500_000 and back.t == 2.5
    assert [m.name for m in back.movers] == ["person 1", "box 1", "ball 1"]
    person = back.by_name("person 1")
    assert person.p_world_m == (10.1235, 9.0, 0.9)  # rounded to 0.1 mm
    assert person.heading_rad == 3.141593 and person.v_world_m_s == (-1.5, 0.0, 0.0)
    assert (person.radius_m, person.height_m) == (0.35, 1.8)
    box = back.by_name("box 1")
    assert (box.length_m, box.width_m, box.height_m) == (3.0, 1.5, 1.6)
    assert back.by_name("ball 1").radius_m == 0.4
    obj = json.loads(encode_movers(s))
    assert set(obj["movers"][2]) == {"name", "shape", "p_world_m", "heading_rad",
                                     "v_world_m_s", "radius_m"}  # only its own sizes
    with pytest.raises(KeyError, match="no mover named 'cart 1'"):
        back.by_name("cart 1")
    assert decode_movers(encode_movers(MoverStates(0, []))).movers == ()


def _movers_obj(**mover) -> dict:
    m = {"name": "person 1", "shape": "person", "p_world_m": [1.0, 2.0, 0.9],
         "heading_rad": 0.0, "v_world_m_s": [1.0, 0.0, 0.0], "radius_m": 0.3,
         "height_m": 1.8}
    m.update(mover)
    return {"v": 1, "t": 1.0, "time_usec": 1_000_000,
            "movers": [{k: v for k, v in m.items() if v is not None}]}


@pytest.mark.parametrize("obj, message", [
    (_movers_obj(radius_m=None), "movers: 'person 1': a person has radius_m, height_m; "
                                 "radius_m is missing"),
    (_movers_obj(width_m=1.0), "a person has radius_m, height_m; width_m is not allowed"),
    (_movers_obj(shape="car"), "Expected `str` matching regex '^(person|box|sphere)$' - at "
                               "`$.movers[0].shape`, got 'car'"),
    (_movers_obj(radius_m=0.0), "Expected `float` > 0.0 - at `$.movers[0].radius_m`, got 0.0"),
    (_movers_obj(heading_rad=4.0), "Expected `float` <= 3.141593 - at "
                                   "`$.movers[0].heading_rad`, got 4.0"),
    (_movers_obj(p_world_m=[1.0, 2.0]), "Expected `array` of length 3"),
    (_movers_obj(name=""), "Expected `str` of length >= 1"),
    (_movers_obj(extra=1), "Object contains unknown field `extra`"),
    ({**_movers_obj(), "v": 2}, "movers: unsupported schema version v=2"),
    ({**_movers_obj(), "t": 2.0}, "movers: t = 2.0 s disagrees with time_usec = 1000000"),
    ({**_movers_obj(), "movers": _movers_obj()["movers"] * 2},
     "movers: name 'person 1' is given twice"),
    ({**_movers_obj(), "movers": _movers_obj()["movers"] * 65}, "length <= 64"),
    ({k: v for k, v in _movers_obj().items() if k != "movers"},
     "Object missing required field `movers`"),
])
def test_movers_decoder_rejects(obj, message):
    with pytest.raises(BusPayloadError) as err:
        decode_movers(dumps(obj))
    assert str(err.value).startswith("movers: ") and message in str(err.value), err.value


@pytest.mark.parametrize("mover, message", [
    ({"p_world_m": (math.nan, 0.0, 0.0)}, "movers: movers[0].p_world_m[0] must be finite"),
    ({"v_world_m_s": (0.0, math.inf, 0.0)}, "movers: movers[0].v_world_m_s[1] must be finite"),
    ({"heading_rad": math.nan}, "`$.movers[0].heading_rad`"),
    ({"radius_m": math.inf}, "`$.movers[0].radius_m`"),
])
def test_movers_reject_non_finite_values(mover, message):
    m = {**_movers_obj()["movers"][0], **mover}
    with pytest.raises(BusPayloadError, match=re.escape(message)):
        MoverStates(1_000_000, [m])
    with pytest.raises(BusPayloadError, match="each mover must be a MoverState or a mapping"):
        MoverStates(0, [42])
    with pytest.raises(BusPayloadError, match="expected a MoverStates"):
        encode_movers({"movers": []})
