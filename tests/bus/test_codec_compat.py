"""The JSON wire format across the move to msgspec: payloads captured from the encoder as
it was before (commit 5da4228, json.dumps) decode to the same values, today's encoder
writes the same JSON for the same inputs, and no malformed payload makes a decoder raise
anything but BusPayloadError."""

import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ft_sitl.bus.codec import (
    EVENT_TYPES,
    BusPayloadError,
    Event,
    EventType,
    OfflineReason,
    Status,
    StatusValue,
    Telemetry,
    decode_config,
    decode_event,
    decode_status,
    decode_telemetry,
    encode_config,
    encode_event,
    encode_status,
    encode_telemetry,
)

T1 = Telemetry(12_345_678, (1.25, -3.5, 10.123456789), np.array([0.1, 0.2, -0.3]),
               (math.cos(0.3), 0.0, 0.0, math.sin(0.3)), [0.01, -0.02, 0.5],
               (0.51, 0.52, 0.49, 0.5))
T2 = Telemetry(0, (0.0, -0.0, 1e-7), (123456.789, -1e-5, 3), (1, 0, 0, 0), (0, 0, 0),
               (0, 1, 0.00005, 0.99999, 0.25, 0.75))

# (value, what json.dumps wrote for it before msgspec)
OLD_TELEMETRY = [
    (T1, b'{"v":1,"t":12.345678,"time_usec":12345678,"p_world_m":[1.25,-3.5,10.123457],'
         b'"v_world_m_s":[0.1,0.2,-0.3],"q_world_body":[0.955336489,0.0,0.0,0.295520207],'
         b'"w_body_rad_s":[0.01,-0.02,0.5],"motors":[0.51,0.52,0.49,0.5]}'),
    (T2, b'{"v":1,"t":0.0,"time_usec":0,"p_world_m":[0.0,0.0,0.0],'
         b'"v_world_m_s":[123456.789,-1e-05,3.0],"q_world_body":[1.0,0.0,0.0,0.0],'
         b'"w_body_rad_s":[0.0,0.0,0.0],"motors":[0.0,1.0,0.0001,1.0,0.25,0.75]}'),
]
OLD_EVENTS = [
    (Event("armed", 1_000_000), b'{"v":1,"type":"armed","t":1.0,"time_usec":1000000}'),
    (Event("mode", 1_500_000, {"mode": "OFFBOARD"}),
     b'{"v":1,"type":"mode","t":1.5,"time_usec":1500000,"mode":"OFFBOARD"}'),
    (Event("collision", 7_250_000, {"object": "tree_3", "speed_m_s": 2.5}),
     b'{"v":1,"type":"collision","t":7.25,"time_usec":7250000,"object":"tree_3",'
     b'"speed_m_s":2.5}'),
    (Event("trial_end", 60_000_000, {"outcome": "success", "path_m": 41.2, "ok": True,
                                     "goal": [5.0, 18.0, 1.5], "note": None, "n": 3}),
     b'{"v":1,"type":"trial_end","t":60.0,"time_usec":60000000,"outcome":"success",'
     b'"path_m":41.2,"ok":true,"goal":[5.0,18.0,1.5],"note":null,"n":3}'),
    (Event("battery_low", 30_000_001, {"remaining": 0.15, "label": 'é ✓ "q"'}),
     b'{"v":1,"type":"battery_low","t":30.000000999999997,"time_usec":30000001,'
     b'"remaining":0.15,"label":"\\u00e9 \\u2713 \\"q\\""}'),
]
OLD_STATUS = [
    (Status("0", True), b'{"v":1,"vehicle":"0","status":"online"}'),
    (Status("uav-7", False, "connection lost"),
     b'{"v":1,"vehicle":"uav-7","status":"offline","reason":"connection lost"}'),
]
OLD_CONFIG = ({"telemetry_rate_hz": 20, "depth": True, "points": False},
              b'{"v":1,"telemetry_rate_hz":20.0,"depth":true,"points":false}')

# json.dumps escaped non-ASCII and wrote -1e-05; msgspec writes UTF-8 and -0.00001: the
# same JSON values, other bytes
DIFFERENT_BYTES = {OLD_TELEMETRY[1][1], OLD_EVENTS[-1][1]}


def same_json(a: bytes, b: bytes):
    """Equal JSON documents, with the same JSON types (int stays int, float float)."""
    def typed(x):
        if isinstance(x, dict):
            return {k: typed(v) for k, v in x.items()}
        if isinstance(x, list):
            return [typed(v) for v in x]
        return (type(x).__name__, x)
    ja, jb = json.loads(a), json.loads(b)
    assert typed(ja) == typed(jb)
    assert list(ja) == list(jb)  # same field order


@pytest.mark.parametrize("value, old", OLD_TELEMETRY + OLD_EVENTS + OLD_STATUS)
def test_old_payloads_decode_and_encoding_is_unchanged(value, old):
    decode, encode = {Telemetry: (decode_telemetry, encode_telemetry),
                      Event: (decode_event, encode_event),
                      Status: (decode_status, encode_status)}[type(value)]
    decoded = decode(old)
    if isinstance(value, Telemetry):  # the encoder rounds; the old payload is rounded
        assert decoded == decode(encode(value))
        np.testing.assert_allclose(decoded.p_world_m, value.p_world_m, atol=5e-7)
    else:
        assert decoded == value
    new = encode(value)
    same_json(new, old)
    if old not in DIFFERENT_BYTES:
        assert new == old


def test_old_config_decodes_and_encoding_is_unchanged():
    config, old = OLD_CONFIG
    assert decode_config(old) == {"telemetry_rate_hz": 20.0, "depth": True, "points": False}
    assert encode_config(config) == old


def test_decoded_values_have_the_old_python_types():
    t = decode_telemetry(OLD_TELEMETRY[1][1])
    assert all(type(x) is float for x in t.v_world_m_s + t.motors)  # 3 -> 3.0, as before
    e = decode_event(OLD_EVENTS[3][1])
    assert type(e.fields["n"]) is int and type(e.fields["path_m"]) is float
    assert e.fields["goal"] == [5.0, 18.0, 1.5] and e.fields["note"] is None


# --- enumerations ---------------------------------------------------------------------------
def test_known_event_types_are_enum_members_and_compare_as_strings():
    e = decode_event(OLD_EVENTS[2][1])
    assert e.type is EventType.COLLISION and e.type == "collision"
    assert set(EVENT_TYPES) == set(EventType)
    assert Event(EventType.MODE, 0, {"mode": "HOLD"}) == Event("mode", 0, {"mode": "HOLD"})


def test_unknown_event_types_are_accepted_as_plain_strings():
    e = decode_event(b'{"v":1,"type":"battery_low","t":1.0,"time_usec":1000000,"pct":15}')
    assert type(e.type) is str and e.type == "battery_low" and e.fields == {"pct": 15}
    assert decode_event(encode_event(e)) == e


@pytest.mark.parametrize("kind, message", [
    ("Battery", "type must match"),
    ("9lives", "type must match"),
    ("x" * 65, "type must match"),
])
def test_malformed_event_types_are_rejected(kind, message):
    with pytest.raises(BusPayloadError, match=message):
        Event(kind, 0)
    payload = json.dumps({"v": 1, "type": kind, "t": 0.0, "time_usec": 0}).encode()
    with pytest.raises(BusPayloadError, match=r"at `\$.type`"):
        decode_event(payload)


def test_status_values_and_reasons_are_enums():
    payload = encode_status(Status("0", False, OfflineReason.CONNECTION_LOST))
    assert json.loads(payload)["status"] == StatusValue.OFFLINE == "offline"
    assert decode_status(payload).reason == "connection lost"


# --- non-JSON bytes and type errors -----------------------------------------------------------
DECODERS = [decode_telemetry, decode_event, decode_status, decode_config]


@pytest.mark.parametrize("decode", DECODERS)
@pytest.mark.parametrize("payload, message", [
    (b"", "not valid JSON"),
    (b"\x00\x01\x02", "not valid JSON"),
    (b"\xc3\x28", "not UTF-8"),
    (b'{"\x80":1}', "not UTF-8"),  # msgspec raised UnicodeDecodeError for this one
    (b"FTSF\x01\x01", "not valid JSON"),
    (b'{"v":-Infinity}', "JSON constant -Infinity is not allowed"),
    (b'{"v": NaN}', "JSON constant NaN is not allowed"),
    (b"[" * 30_000 + b"]" * 30_000, "Expected `object`, got `array`"),
    (b'{"v":' + b"[" * 30_000 + b"]" * 30_000 + b"}",
     r"at `\$.v`|nested too deeply to decode"),
    (b"null", "Expected `object`, got `null`"),
    (b'{"v":1,"v":1', "not valid JSON"),
])
def test_non_json_and_wrong_types_answer_with_bus_payload_error(decode, payload, message):
    with pytest.raises(BusPayloadError, match=message):
        decode(payload)


JSON_VALUES = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats(allow_nan=False,
                                                          allow_infinity=False) | st.text(),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(), inner, max_size=4),
    max_leaves=12)
KEYS = st.sampled_from(["v", "t", "time_usec", "type", "p_world_m", "motors", "q_world_body",
                        "vehicle", "status", "reason", "depth", "telemetry_rate_hz", "object",
                        "speed_m_s", "x"])


@pytest.mark.slow
@settings(max_examples=300, deadline=None)
@given(st.dictionaries(KEYS, JSON_VALUES, max_size=8))
def test_json_objects_never_raise_anything_but_bus_payload_error(obj):
    payload = json.dumps(obj).encode()
    for decode in DECODERS:
        try:
            decode(payload)
        except BusPayloadError:
            pass


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=200), st.integers(0, 300))
def test_corrupted_payloads_never_raise_anything_but_bus_payload_error(noise, at):
    for good in (OLD_TELEMETRY[0][1], OLD_EVENTS[3][1], OLD_STATUS[1][1], OLD_CONFIG[1]):
        for payload in (noise, good[:at] + noise + good[at + len(noise):], good[:at]):
            for decode in DECODERS:
                try:
                    decode(payload)
                except BusPayloadError:
                    pass
