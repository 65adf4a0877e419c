"""Publisher -> broker -> client through real brokers (mosquitto and the embedded amqtt):
round trips, retained status and last will, config requests, TLS."""

from __future__ import annotations

import asyncio
import logging
import queue
import secrets
import subprocess
import sys

import numpy as np
import pytest

from ft_sitl.bus import BusClient, BusPublisher, MoverState, MoverStates, TlsOptions
from ft_sitl.bus.tick import Tick

from .busutil import DEADLINE_S, receive_until, telemetry, wait_until

MOVER = {"name": "box 2", "shape": "box", "p_world_m": (4.5, -2.0, 0.8), "heading_rad": 1.25,
         "v_world_m_s": (0.5, 1.5, 0.0), "length_m": 3.0, "width_m": 1.5, "height_m": 1.6}
ALL_KINDS = ("telemetry", "events", "depth", "points", "movers", "status", "tick")
#: a lockstep tick with the kinds of fields an observation carries
TICK = Tick(7, "step", 2_500_000, {"yaw": 0.1 + 0.2, "has_depth": 1},
            {"position": np.array([1.0 / 3.0, -2.5, 1.5e-300]),
             "depth": np.arange(12, dtype=np.float32).reshape(3, 4)})


@pytest.fixture
def vehicle() -> str:
    """A vehicle name of its own per test (retained status stays on the session brokers)."""
    return f"t{secrets.token_hex(4)}"


@pytest.mark.e2e
def test_round_trip_every_kind(broker_url, vehicle, depth_sample):
    frame, config = depth_sample
    with BusPublisher(broker_url, vehicle) as pub:
        assert pub.wait_connected(DEADLINE_S), pub.stats()

        async def scenario():
            async with BusClient(broker_url, vehicle, kinds=ALL_KINDS) as client:
                status = await receive_until(client, lambda m: m.kind == "status",
                                             "the retained online status")
                assert status.retained and status.data.online and status.vehicle == vehicle
                samples = [telemetry(i) for i in range(5)]
                for s in samples:
                    assert pub.publish_telemetry(s)
                assert pub.publish_event("collision", 1_200_000, object="box_1",
                                         speed_m_s=1.25)
                assert pub.publish_depth(frame, config)
                assert pub.publish_points(frame, config, "body")
                assert pub.publish_movers(MoverStates(1_300_000, [MOVER]))
                assert pub.publish_tick(TICK)
                got = {k: [] for k in ALL_KINDS}

                def complete(msg):
                    got[msg.kind].append(msg)
                    return (len(got["telemetry"]) == 5 and got["events"] and got["depth"]
                            and got["points"] and got["movers"] and got["tick"])

                await receive_until(client, complete, "5 telemetry, 1 event, 1 depth frame, "
                                                      "1 point cloud, 1 movers state, 1 tick")
                return samples, got

        samples, got = asyncio.run(scenario())
        stats = pub.stats()
    assert [m.data.time_usec for m in got["telemetry"]] == [s.time_usec for s in samples]
    np.testing.assert_allclose(got["telemetry"][3].data.p_world_m, (3.0, 6.0, 1.5))
    event = got["events"][0]
    assert event.vehicle == vehicle and event.topic == f"ft-sitl/v1/{vehicle}/events"
    assert event.data.type == "collision" and event.data.fields == {"object": "box_1",
                                                                    "speed_m_s": 1.25}
    back = got["depth"][0].data.to_depth_frame()
    valid = np.isfinite(frame.depth)
    np.testing.assert_array_equal(np.isfinite(back.depth), valid)
    np.testing.assert_allclose(back.depth[valid], frame.depth[valid], atol=5.01e-4)
    points = got["points"][0].data
    assert points.frame == "body"
    np.testing.assert_allclose(points.points, frame.points_body, rtol=1e-6, atol=1e-5)
    movers = got["movers"][0].data
    assert movers.time_usec == 1_300_000 and movers.movers == (MoverState(**MOVER),)
    tick = got["tick"][0].data  # exactly: the lockstep observation's bits
    assert (tick.seq, tick.phase, tick.time_usec, tick.scalars) == (
        TICK.seq, TICK.phase, TICK.time_usec, TICK.scalars)
    assert tick.arrays.keys() == TICK.arrays.keys()
    for name, a in TICK.arrays.items():
        assert tick.arrays[name].dtype == a.dtype
        np.testing.assert_array_equal(tick.arrays[name], a)
    assert stats.sent == {"events": 1, "telemetry": 5, "movers": 1, "depth": 1, "points": 1,
                          "tick": 1}
    assert stats.dropped == {"events": 0, "telemetry": 0, "movers": 0, "depth": 0,
                             "points": 0, "tick": 0}
    assert stats.connects == 1 and stats.reconnects == 0 and stats.last_error is None


@pytest.mark.e2e
def test_status_online_then_closed(broker_url, vehicle):
    pub = BusPublisher(broker_url, vehicle).start()
    assert pub.wait_connected(DEADLINE_S), pub.stats()

    async def read_status():
        async with BusClient(broker_url, vehicle, kinds=("status",)) as client:
            return await receive_until(client, lambda m: True, "the retained status")

    online = asyncio.run(read_status())
    assert online.retained and online.data.online and online.data.reason is None
    pub.close()
    pub.close()  # safe twice
    offline = asyncio.run(read_status())
    assert offline.retained and not offline.data.online and offline.data.reason == "closed"
    assert not pub.stats().connected
    assert not pub.publish_telemetry(telemetry(0))  # after close: dropped, counted
    assert pub.stats().dropped["telemetry"] == 1


CHILD = """
import sys, time
from ft_sitl.bus import BusPublisher
pub = BusPublisher(sys.argv[1], sys.argv[2]).start()
if not pub.wait_connected(float(sys.argv[3])):
    sys.exit(f"no connection: {pub.stats()}")
print("connected", flush=True)
time.sleep(600)
"""


@pytest.mark.e2e
def test_last_will_when_the_publisher_dies(broker_url, vehicle):
    async def scenario(proc):
        async with BusClient(broker_url, vehicle, kinds=("status",)) as client:
            online = await receive_until(client, lambda m: True, "the retained status")
            assert online.data.online
            proc.kill()  # no DISCONNECT: the broker sees the connection die
            return await receive_until(client, lambda m: not m.data.online, "the last will")

    with subprocess.Popen([sys.executable, "-c", CHILD, broker_url, vehicle, str(DEADLINE_S)],
                          stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) as proc:
        try:
            line = proc.stdout.readline()
            assert line == "connected\n", proc.stderr.read() if proc.poll() is not None else line
            will = asyncio.run(scenario(proc))
        finally:
            proc.kill()
    assert will.data.reason == "connection lost" and will.vehicle == vehicle

    async def late_reader():  # the will is retained for clients that come later
        async with BusClient(broker_url, vehicle, kinds=("status",)) as client:
            return await receive_until(client, lambda m: True, "the retained will")

    late = asyncio.run(late_reader())
    assert late.retained and not late.data.online and late.data.reason == "connection lost"


@pytest.mark.e2e
def test_config_requests_accepted_and_rejected(broker_url, vehicle, caplog):
    caplog.set_level(logging.INFO, logger="ft_sitl.bus")
    configs: queue.SimpleQueue = queue.SimpleQueue()

    def on_config(cfg):
        if cfg.get("points"):
            raise RuntimeError("this simulator cannot do points")
        configs.put(cfg)

    bad = {
        b"{not json": "payload is not valid JSON",
        b'{"depth": "yes"}': "Expected `bool`, got `str` - at `$.depth`",
        b'{"telemetry_rate_hz": 5000}': "Expected `float` <= 1000.0 - at "
                                        "`$.telemetry_rate_hz`, got 5000",
        b'{"video": true}': "Object contains unknown field `video`",
        b'["depth"]': "Expected `object`, got `array`",
    }
    with BusPublisher(broker_url, vehicle, on_config=on_config) as pub:
        assert pub.wait_connected(DEADLINE_S), pub.stats()

        async def scenario():
            async with BusClient(broker_url, vehicle, kinds=("telemetry",)) as client:
                await client.request_config(telemetry_rate_hz=20, depth=True, points=False)
                for payload in bad:
                    await client.publish_raw("config", payload)
                await client.request_config(points=True)  # the callback raises
                wait_until(lambda: pub.stats().config_rejected == len(bad)
                           and pub.stats().callback_errors == 1,
                           "the bus to process the config requests")
                # publishing goes on
                assert pub.publish_telemetry(telemetry(7))
                msg = await receive_until(client, lambda m: True, "telemetry after the "
                                                                   "rejected configs")
                return msg

        msg = asyncio.run(scenario())
        stats = pub.stats()
    assert msg.data.time_usec == telemetry(7).time_usec
    assert configs.get_nowait() == {"telemetry_rate_hz": 20.0, "depth": True, "points": False}
    assert configs.empty()
    assert stats.config_accepted == 2 and stats.config_rejected == len(bad)
    assert stats.connected and stats.reconnects == 0
    rejected = [r.getMessage() for r in caplog.records
                if r.name == "ft_sitl.bus" and r.levelno == logging.WARNING
                and "rejected config request" in r.getMessage()]
    assert len(rejected) == len(bad)
    for reason, line in zip(bad.values(), rejected):
        assert f"ft-sitl/v1/{vehicle}/config" in line and reason in line, (reason, line)
    assert any("on_config callback raised" in r.getMessage() and r.exc_info
               for r in caplog.records if r.name == "ft_sitl.bus")


@pytest.mark.e2e
def test_client_skips_malformed_messages(broker_url, vehicle, caplog):
    caplog.set_level(logging.WARNING, logger="ft_sitl.bus")

    async def scenario():
        async with BusClient(broker_url, vehicle, kinds=("telemetry", "depth", "movers")) \
                as client:
            async with BusClient(broker_url, vehicle, kinds=("status",)) as sender:
                await sender.publish_raw("telemetry", b'{"v": 1}')
                await sender.publish_raw("depth", b"FTSF\x01")
                await sender.publish_raw("movers", b'{"v":1,"t":0,"time_usec":0,'
                                                   b'"movers":[{"name":"x"}]}')
                from ft_sitl.bus import encode_telemetry

                await sender.publish_raw("telemetry", encode_telemetry(telemetry(3)))
            msg = await receive_until(client, lambda m: True, "the valid telemetry")
            return msg, client.rejected

    msg, rejected = asyncio.run(scenario())
    assert msg.data.time_usec == telemetry(3).time_usec and rejected == 3
    lines = [r.getMessage() for r in caplog.records if "skipped malformed" in r.getMessage()]
    assert any("Object missing required field `t`" in s for s in lines)
    assert any("truncated: 5 bytes" in s for s in lines)
    assert any("on ft-sitl/v1/" in s and "/movers: movers: Object missing required field "
               "`shape` - at `$.movers[0]`" in s for s in lines), lines


def test_publish_before_start_is_an_error():
    pub = BusPublisher("mqtt://127.0.0.1:1", "0")
    with pytest.raises(RuntimeError, match=r"start\(\) has not been called"):
        pub.publish_telemetry(telemetry(0))
    pub.close()  # closing an unstarted publisher is fine
    with pytest.raises(RuntimeError, match="was closed"):
        pub.start()


@pytest.mark.parametrize("kwargs, message", [
    ({"queue_size": 0}, "queue_size must be a positive integer"),
    ({"frame_queue_size": 1.5}, "frame_queue_size must be a positive integer"),
    ({"reconnect_min_s": 3.0, "reconnect_max_s": 1.0}, "reconnect_max_s .* must be >="),
    ({"timeout_s": 0}, "timeout_s must be a positive number"),
    ({"on_config": 5}, "on_config must be callable"),
])
def test_publisher_rejects_bad_arguments(kwargs, message):
    with pytest.raises(ValueError, match=message):
        BusPublisher("mqtt://localhost", "0", **kwargs)
    with pytest.raises(ValueError, match="scheme must be mqtt:// or mqtts://"):
        BusPublisher("tcp://localhost", "0")
    with pytest.raises(ValueError, match="vehicle must be 1 to 64 characters"):
        BusPublisher("mqtt://localhost", "a/b")


# --- TLS ----------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def tls_files(tmp_path_factory):
    """A throw-away CA and a server certificate for 127.0.0.1, made with openssl."""
    d = tmp_path_factory.mktemp("tls")

    def run(*args):
        proc = subprocess.run(["openssl", *args], cwd=d, capture_output=True, text=True,
                              timeout=60)
        assert proc.returncode == 0, proc.stderr

    run("req", "-x509", "-newkey", "rsa:2048", "-nodes", "-keyout", "ca.key", "-out",
        "ca.pem", "-days", "2", "-subj", "/CN=ft-sitl test CA")
    run("req", "-newkey", "rsa:2048", "-nodes", "-keyout", "server.key", "-out",
        "server.csr", "-subj", "/CN=127.0.0.1")
    (d / "ext.cnf").write_text("subjectAltName=IP:127.0.0.1\nbasicConstraints=CA:FALSE\n"
                               "extendedKeyUsage=serverAuth\n")
    run("x509", "-req", "-in", "server.csr", "-CA", "ca.pem", "-CAkey", "ca.key",
        "-CAcreateserial", "-out", "server.pem", "-days", "2", "-extfile", "ext.cnf")
    return {"ca": str(d / "ca.pem"), "cert": str(d / "server.pem"),
            "key": str(d / "server.key")}


@pytest.mark.e2e
def test_tls_round_trip(mosquitto_factory, tls_files, vehicle):
    broker = mosquitto_factory(tls=tls_files).start()
    tls = TlsOptions(ca_file=tls_files["ca"])
    with BusPublisher(broker.url, vehicle, tls=tls) as pub:
        assert pub.wait_connected(DEADLINE_S), pub.stats()

        async def scenario():
            async with BusClient(broker.url, vehicle, tls=tls) as client:
                assert pub.publish_telemetry(telemetry(1))
                return await receive_until(client, lambda m: m.kind == "telemetry",
                                           "telemetry over TLS")

        assert asyncio.run(scenario()).data.time_usec == telemetry(1).time_usec

    # insecure: no verification of the certificate (tests only), the connection works
    with BusPublisher(broker.url, vehicle, tls=TlsOptions(insecure=True)) as insecure:
        assert insecure.wait_connected(DEADLINE_S), insecure.stats()

    # the system CA store does not know the throw-away CA: the connection is refused, and
    # the reason is reported
    untrusted = BusPublisher(broker.url, vehicle, reconnect_max_s=0.5).start()
    try:
        wait_until(lambda: untrusted.stats().connect_failures >= 1, "a failed TLS connect")
        stats = untrusted.stats()
        assert not stats.connected and "CERTIFICATE_VERIFY_FAILED" in stats.last_error, stats
    finally:
        untrusted.close()
