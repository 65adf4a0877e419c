"""Instance numbers 40 apart share a UDP port (instance i's client port 14540+i is instance
i-40's API listen port): the numbers taken automatically share no port with each other nor
with 0..19, and holding a number makes every number that shares a port with it busy, in
either order (ft_sitl.mavlink.instances)."""

import pytest

from ft_sitl.mavlink.instances import (
    AUTO_INSTANCES,
    InstanceBusy,
    InstanceLock,
    free_instances,
    instances_held,
)
from ft_sitl.mavlink.ports import instance_ports

# numbers no other test or program uses (and their partners 40 apart)
BASE = 600


def _ports(i: int) -> set[int]:
    return set(instance_ports(i).values())


def test_the_auto_numbers_share_no_port_with_each_other_nor_with_0_to_19():
    assert len(AUTO_INSTANCES) == 40 and len(set(AUTO_INSTANCES)) == 40
    numbers = list(AUTO_INSTANCES) + list(range(20))
    for a in numbers:
        for b in numbers:
            if a != b:
                assert not _ports(a) & _ports(b), (a, b, _ports(a) & _ports(b))
    # the old range 20..59 did not hold: 43's client port is 3's API listen port
    assert _ports(43) & _ports(3) == {14583}


@pytest.mark.parametrize("partner", [BASE + 40, BASE - 40])
def test_a_held_number_makes_the_numbers_sharing_its_ports_busy(partner):
    shared = (_ports(BASE) & _ports(partner)).pop()
    with instances_held(BASE):
        with pytest.raises(InstanceBusy, match=rf"^SITL instance {partner} \(ports .*\) is in "
                                               rf"use by .*: its port {shared} is another "
                                               rf"held instance number's$"):
            with instances_held(partner):
                pass
        with instances_held(BASE + 80), instances_held(BASE + 1):  # no shared port: free
            pass
    with instances_held(partner):  # let go with the holder
        with pytest.raises(InstanceBusy, match=f"its port {shared} "):
            with instances_held(BASE):  # and the other way round
                pass


@pytest.mark.e2e  # (InstanceLock tries each number's ports: a bind)
def test_automatic_picks_skip_numbers_sharing_a_port_with_a_held_one():
    with instances_held(BASE + 40):  # shares 14580+BASE with BASE
        with free_instances(1, base=BASE, slots=3) as first:
            assert first == BASE + 1
        with InstanceLock(base=BASE, slots=3) as i:
            assert i == BASE + 1
        with free_instances(2, base=BASE, slots=3) as first:  # a run of two: past it
            assert first == BASE + 1
        with pytest.raises(InstanceBusy, match=rf"free in {BASE}..{BASE} \(each held by "):
            with free_instances(1, base=BASE, slots=1):
                pass
    with free_instances(1, base=BASE, slots=3) as first:  # let go: free again
        assert first == BASE


@pytest.mark.e2e  # (InstanceLock tries each number's ports: a bind)
def test_a_trials_number_comes_from_the_auto_numbers():
    with InstanceLock() as i, free_instances(1) as j:
        assert i in AUTO_INSTANCES and j in AUTO_INSTANCES and i != j
        assert not _ports(i) & _ports(j)
        assert not any(_ports(i) & _ports(k) for k in range(20))


@pytest.mark.e2e
@pytest.mark.parametrize("role", ["api_listen", "gcs_listen", "client"])
def test_a_trials_number_skips_one_whose_port_another_program_holds(role):
    # (2026-12-07: a lockstep trial took a number by its locks while a socket outside them
    # held its API port, and its server failed with "Address already in use")
    import socket

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as foreign:
        foreign.bind(("127.0.0.1", instance_ports(BASE)[role]))
        with InstanceLock(base=BASE, slots=3) as i:
            assert i == BASE + 1
        with pytest.raises(RuntimeError, match=rf"no free SITL instance in {BASE}..{BASE} "
                                               r"\(.*a port another program holds\)"):
            with InstanceLock(base=BASE, slots=1):
                pass
    with InstanceLock(base=BASE, slots=3) as i:  # let go: free again
        assert i == BASE
