"""The publisher against brokers that die, freeze, come back or are not there yet: publish
calls keep returning (dropping and counting), and the publisher reconnects by itself."""

from __future__ import annotations

import asyncio
import logging
import threading

import pytest

from ft_sitl.bus import BusClient, BusPublisher, EmbeddedBroker

from .busutil import DEADLINE_S, free_port, receive_until, telemetry, wait_until

pytestmark = pytest.mark.e2e  # (tests/lanes.py)


def bus_thread_alive(vehicle: str) -> bool:
    return any(t.name == f"ft-sitl-bus-{vehicle}" and t.is_alive()
               for t in threading.enumerate())


def retained_status(url: str, vehicle: str):
    async def read():
        async with BusClient(url, vehicle, kinds=("status",)) as client:
            return (await receive_until(client, lambda m: True, "the retained status")).data

    return asyncio.run(read())


def flows(url: str, vehicle: str, pub: BusPublisher, i: int = 0) -> float:
    """Subscribe afresh and check that published telemetry arrives (and the retained status
    says online); returns the received sample's time."""

    async def scenario():
        async with BusClient(url, vehicle, kinds=("telemetry", "status")) as client:
            status = await receive_until(client, lambda m: m.kind == "status",
                                         "the retained status")
            assert status.data.online
            assert pub.publish_telemetry(telemetry(i))
            msg = await receive_until(client, lambda m: m.kind == "telemetry", "telemetry")
            return msg.data.time_usec

    return asyncio.run(scenario())


def test_broker_killed_and_restarted(mosquitto_factory, depth_sample, caplog):
    caplog.set_level(logging.INFO, logger="ft_sitl.bus")
    frame, config = depth_sample
    broker = mosquitto_factory().start()
    pub = BusPublisher(broker.url, "k", reconnect_max_s=0.5).start()
    try:
        assert pub.wait_connected(DEADLINE_S), pub.stats()
        assert flows(broker.url, "k", pub, 1) == telemetry(1).time_usec

        broker.kill()
        # keep streaming while the publisher notices; every call returns
        wait_until(lambda: not pub.publish_telemetry(telemetry(2)) and not pub.connected,
                   "the publisher to notice the dead broker")
        before = pub.stats()
        results = [pub.publish_telemetry(telemetry(3)) for _ in range(200)]
        results += [pub.publish_event("collision", 5, object="x", speed_m_s=1.0),
                    pub.publish_depth(frame, config), pub.publish_points(frame, config)]
        after = pub.stats()
        assert not any(results)
        assert after.dropped["telemetry"] == before.dropped["telemetry"] + 200
        assert after.dropped["events"] == before.dropped["events"] + 1
        assert after.dropped["depth"] == before.dropped["depth"] + 1
        assert after.dropped["points"] == before.dropped["points"] + 1
        assert not after.connected and after.last_error
        assert any("connection to" in r.getMessage() and "lost" in r.getMessage()
                   for r in caplog.records if r.levelno == logging.WARNING)

        broker.start()  # the same port
        wait_until(lambda: pub.stats().connected, "the publisher to reconnect")
        assert pub.stats().reconnects == 1
        assert flows(broker.url, "k", pub, 4) == telemetry(4).time_usec
    finally:
        pub.close()
    assert not bus_thread_alive("k")


def test_broker_absent_at_start(mosquitto_factory):
    port = free_port()
    pub = BusPublisher(f"mqtt://127.0.0.1:{port}", "late", reconnect_max_s=0.5).start()
    try:
        wait_until(lambda: pub.stats().connect_failures >= 2, "two failed connection attempts")
        assert not pub.publish_telemetry(telemetry(0))
        stats = pub.stats()
        assert not stats.connected and stats.connects == 0
        assert stats.dropped["telemetry"] == 1
        assert "refused" in stats.last_error.lower(), stats.last_error

        broker = mosquitto_factory(port).start()
        wait_until(lambda: pub.stats().connected, "the publisher to connect to the new broker")
        assert pub.stats().connects == 1 and pub.stats().reconnects == 0
        assert flows(broker.url, "late", pub) == telemetry(0).time_usec
    finally:
        pub.close()
    assert not bus_thread_alive("late")


def test_frozen_broker_drops_frames_then_recovers(mosquitto_factory, depth_sample):
    """A broker that stops reading (SIGSTOP): the socket buffers fill, the frame queue fills,
    frames are dropped and counted, the publisher gives the connection up after timeout_s;
    once the broker runs again, frames flow again."""
    frame, config = depth_sample
    broker = mosquitto_factory().start()
    pub = BusPublisher(broker.url, "slow", frame_queue_size=2, timeout_s=2.0,
                       reconnect_max_s=0.5).start()
    try:
        assert pub.wait_connected(DEADLINE_S), pub.stats()
        broker.freeze()
        wait_until(lambda: (pub.publish_depth(frame, config), pub.stats().dropped["depth"] > 0)[1],
                   "depth frames to be dropped while the broker is frozen", interval=0.001)
        # the stream goes on until the socket buffers are full and a publish times out
        wait_until(lambda: (pub.publish_depth(frame, config), not pub.stats().connected)[1],
                   "the publisher to give up the stalled connection", interval=0.005)
        assert not pub.publish_depth(frame, config)
        broker.thaw()
        wait_until(lambda: pub.stats().connected, "the publisher to reconnect after the thaw")

        async def scenario():
            async with BusClient(broker.url, "slow", kinds=("depth",)) as client:
                async def feed():
                    while True:  # a stream, as the simulator would send it
                        pub.publish_depth(frame, config)
                        await asyncio.sleep(0.05)

                feeder = asyncio.create_task(feed())
                try:
                    return await receive_until(client, lambda m: True, "a depth frame")
                finally:
                    feeder.cancel()

        msg = asyncio.run(scenario())
        assert msg.data.time_usec == frame.t_us
        assert pub.stats().reconnects >= 1
        # the connection attempts made while the broker was frozen were closed, so the
        # retained status settles on online (their wills, if any, came first)
        wait_until(lambda: retained_status(broker.url, "slow").online and pub.connected,
                   "the retained status to say online")
    finally:
        broker.thaw()
        pub.close()
    assert not bus_thread_alive("slow")


def test_close_is_prompt_while_frozen(mosquitto_factory):
    """close() with a stalled broker gives up after close_timeout_s instead of hanging."""
    broker = mosquitto_factory().start()
    pub = BusPublisher(broker.url, "stuck", close_timeout_s=0.5, timeout_s=30.0).start()
    try:
        assert pub.wait_connected(DEADLINE_S), pub.stats()
        broker.freeze()
        for i in range(50):
            pub.publish_event("note", i, text="x" * 1000)
    finally:
        pub.close()
        broker.thaw()
    assert not bus_thread_alive("stuck")


def test_close_while_broker_absent():
    pub = BusPublisher(f"mqtt://127.0.0.1:{free_port()}", "never").start()
    wait_until(lambda: pub.stats().connect_failures >= 1, "a failed connection attempt")
    pub.close()
    pub.close()
    assert not bus_thread_alive("never")
    assert not pub.publish_telemetry(telemetry(0))


def test_embedded_broker_restart():
    broker = EmbeddedBroker().start()
    port = broker.port
    pub = BusPublisher(broker.url, "emb", reconnect_max_s=0.5).start()
    try:
        assert pub.wait_connected(DEADLINE_S), pub.stats()
        broker.stop()
        wait_until(lambda: not pub.stats().connected, "the publisher to see the broker stop")
        assert not pub.publish_telemetry(telemetry(0))
        broker = EmbeddedBroker(port=port).start()
        wait_until(lambda: pub.stats().connected, "the publisher to reconnect")
        assert flows(broker.url, "emb", pub, 5) == telemetry(5).time_usec
    finally:
        pub.close()
        broker.stop()
