"""RateGate in simulated time, and the EmbeddedBroker's life cycle."""

import asyncio

import pytest

from ft_sitl.bus import BusClient, EmbeddedBroker, RateGate


# --- RateGate -----------------------------------------------------------------------------------
def count_samples(gate: RateGate, step_us: int, duration_us: int, start_us: int = 0) -> list:
    return [t for t in range(start_us, start_us + duration_us, step_us) if gate.take(t)]


def test_rate_gate_counts_without_drift():
    # 20 Hz stepped at 3 ms (the period is not a multiple of the step): 20 per second
    taken = count_samples(RateGate(20.0), 3000, 10_000_000)
    assert len(taken) == 200
    assert taken[:3] == [0, 51_000, 102_000]  # first step at or after 0, 50, 100 ms
    # 30 Hz at 1 kHz: 30 per second
    assert len(count_samples(RateGate(30.0), 1000, 1_000_000)) == 30


def test_rate_gate_due_does_not_consume():
    gate = RateGate(10.0)
    assert gate.next_due_us is None and gate.due(5)
    assert gate.take(5) and gate.next_due_us == 100_005
    assert not gate.due(100_004) and gate.due(100_005) and gate.due(100_005)
    assert gate.take(100_005) and not gate.take(100_006)


def test_rate_gate_late_caller_gets_one_sample():
    gate = RateGate(100.0)
    assert gate.take(0)
    assert gate.take(1_000_000)          # 100 slots late: one sample, not a burst
    assert not gate.take(1_000_001)
    assert gate.next_due_us == 1_010_000


def test_rate_gate_zero_rate_and_changes():
    gate = RateGate(0)
    assert not gate.take(0) and not gate.take(10**9) and gate.next_due_us is None
    gate.set_rate(50.0)
    assert gate.take(123) and gate.next_due_us == 20_123
    gate.set_rate(10.0)                  # re-anchored: the next sample is due at once
    assert gate.take(200) and gate.next_due_us == 100_200


def test_rate_gate_time_going_backwards_reanchors():
    gate = RateGate(10.0)
    assert gate.take(5_000_000)
    assert gate.take(0)                  # a reset simulation
    assert gate.next_due_us == 100_000


@pytest.mark.parametrize("rate", [-1.0, float("nan"), float("inf"), 2e6, "20", True])
def test_rate_gate_rejects_bad_rates(rate):
    with pytest.raises(ValueError, match="rate_hz must be a number in"):
        RateGate(rate)


# --- EmbeddedBroker -----------------------------------------------------------------------------
@pytest.mark.e2e
def test_embedded_broker_life_cycle():
    broker = EmbeddedBroker()
    with pytest.raises(RuntimeError, match="not running: call start"):
        _ = broker.url
    broker.start()
    try:
        assert broker.running and broker.url == f"mqtt://127.0.0.1:{broker.port}"
        broker.start()  # idempotent

        async def connect():
            async with BusClient(broker.url, "0") as client:
                await client.request_config(depth=True)

        asyncio.run(connect())
    finally:
        broker.stop()
    assert not broker.running
    broker.stop()  # idempotent


@pytest.mark.e2e
def test_embedded_broker_given_port_and_port_in_use():
    first = EmbeddedBroker().start()
    port = first.port
    try:
        second = EmbeddedBroker(port=port)
        with pytest.raises(RuntimeError, match=f"could not start the embedded MQTT broker on "
                                               f"127.0.0.1:{port}: .*in use"):
            second.start()
        assert not second.running
    finally:
        first.stop()
    # the port is free again: a broker on that given port starts
    again = EmbeddedBroker(port=port).start()
    try:
        assert again.port == port
    finally:
        again.stop()


@pytest.mark.parametrize("kwargs, message", [
    ({"port": 0}, r"port must be an integer in \[1, 65535\] or None"),
    ({"port": 70000}, r"port must be an integer in \[1, 65535\] or None"),
    ({"host": ""}, "host must be a non-empty string"),
])
def test_embedded_broker_rejects_bad_arguments(kwargs, message):
    with pytest.raises(ValueError, match=message):
        EmbeddedBroker(**kwargs)
