"""``ft-sitl sitl --instance auto`` takes free instance numbers atomically, skipping numbers
whose ports another program holds; a taken port is an error naming the port and its
holder (ft_sitl.mavlink.instances.free_instances, ft_sitl.mavlink.ports)."""

import json
import os
import socket
import subprocess
import sys
import time

import pytest

from ft_sitl.mavlink.instances import InstanceBusy, free_instances, instances_held
from ft_sitl.mavlink.ports import (
    instance_ports,
    port_holders,
    taken_message,
    taken_ports,
    udp_port_free,
)

# numbers far above the SITLs' own (0..59): no other test or program uses them
HIGH = 900


def test_free_instances_skips_held_and_unusable_numbers():
    with instances_held(HIGH + 1):  # held by "another process" (another open lock file)
        with free_instances(2, usable=lambda i: i != HIGH + 3, base=HIGH, slots=8) as first:
            # HIGH is free but HIGH + 1 is held, HIGH + 2 free but HIGH + 3 unusable
            assert first == HIGH + 4
            with pytest.raises(InstanceBusy, match=f"SITL instance {HIGH + 4} "):
                with instances_held(HIGH + 4):
                    pass
        with instances_held(HIGH + 4, 2):  # let go when the context ended
            pass


def test_free_instances_names_the_range_when_none_is_free():
    with instances_held(HIGH, 2):
        with pytest.raises(InstanceBusy, match=rf"no 1 consecutive SITL instance numbers "
                                               rf"free in {HIGH}..{HIGH + 1} "):
            with free_instances(1, base=HIGH, slots=2):
                pass


def test_instance_ports_are_px4_sitls():
    assert instance_ports(3) == {"client": 14543, "api_listen": 14583, "gcs_listen": 18573}


@pytest.mark.e2e
def test_a_taken_port_names_its_holder():
    i = HIGH + 20
    port = instance_ports(i)["gcs_listen"]
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", port))
        assert taken_ports(i, "127.0.0.1", client=False) == [("gcs_listen", port)]
        holders = port_holders(port)
        assert holders is not None and any(h.startswith(f"pid {os.getpid()} (") for h in holders)
        msg = taken_message(i, [("gcs_listen", port)])
        assert msg.startswith(f"UDP port {port} (the GCS listen port of instance {i}) is held "
                              f"by pid {os.getpid()} (")
        r = subprocess.run([sys.executable, "-m", "ft_sitl", "sitl", "--instance", str(i),
                            "--no-mqtt", "--duration", "1"], capture_output=True, text=True,
                           timeout=300)
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1, r.stderr
    assert lines[0].startswith(f"ft-sitl: error: cannot listen on 127.0.0.1: UDP port {port} "
                               f"(the GCS listen port of instance {i}) is held by pid "
                               f"{os.getpid()} ("), lines


@pytest.mark.e2e
def test_the_holder_of_a_tcp_port_is_named_too():
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        holders = port_holders(s.getsockname()[1])
    assert holders is not None and any(h.startswith(f"pid {os.getpid()} (") for h in holders)


def _start_auto(*args):
    return subprocess.Popen([sys.executable, "-m", "ft_sitl", "sitl", "--instance", "auto",
                             "--json", "--no-mqtt", *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


def _read_json(proc) -> dict:
    """The JSON the sitl prints once its numbers are held and its ports bound (before it
    simulates)."""
    text = ""
    for line in proc.stdout:
        text += line
        if line.rstrip() == "}":
            return json.loads(text)
    raise AssertionError(f"no JSON; stderr: {proc.stderr.read()}")


@pytest.mark.e2e
def test_concurrent_auto_sitls_take_different_numbers_and_skip_taken_ports():
    procs = []
    # a client already listening on the first free number's client port (as one left by an
    # earlier test would): auto must not pick that number
    with free_instances(1) as first:
        pass
    client = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    client.bind(("0.0.0.0", instance_ports(first)["client"]))
    try:
        procs = [_start_auto("--instances", "2"), _start_auto()]
        outs = [_read_json(p) for p in procs]
        numbers = [v["instance"] for o in outs for v in o["vehicles"]]
        # the JSON comes once the server listens: a script may connect as soon as it reads
        # it (before, it came first and the ports were bound after it)
        for v in outs[0]["vehicles"] + outs[1]["vehicles"]:
            assert not udp_port_free("127.0.0.1", v["ports"]["api_listen"]), v
            assert not udp_port_free("127.0.0.1", v["ports"]["gcs_listen"]), v
        assert len(set(numbers)) == 3, numbers
        assert first not in numbers
        a, b = outs
        assert a["vehicles"][1]["instance"] == a["vehicles"][0]["instance"] + 1
        for v in a["vehicles"] + b["vehicles"]:
            ports = instance_ports(v["instance"])
            assert v["ports"] == ports
            assert v["mavsdk"] == f"udpin://0.0.0.0:{ports['client']}"
            assert v["pymavlink"] == f"udpin:0.0.0.0:{ports['client']}"
        # while they run, their numbers are held
        for n in numbers:
            with pytest.raises(InstanceBusy):
                with instances_held(n):
                    pass
    finally:
        client.close()
        for p in procs:
            p.terminate()
        for p in procs:
            p.wait(60)
            p.stdout.close()
            p.stderr.close()
    deadline = time.monotonic() + 60  # let go at exit (a ceiling against a hang only)
    while True:
        try:
            with instances_held(numbers[0], 1):
                break
        except InstanceBusy:
            assert time.monotonic() < deadline
            time.sleep(0.1)
