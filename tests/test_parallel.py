"""The suite's parallel run (tests/conftest.py): the files that use the SITL's fixed MAVLink
ports share one xdist worker, handed out first; every other file (those that take instance
numbers through the allocation among them) is run whole by one."""

import re
from pathlib import Path
from types import SimpleNamespace

from .conftest import (
    ALLOCATED,
    FIXED_PORTS_GROUP,
    group_of,
    pytest_xdist_make_scheduler,
)

TESTS = Path(__file__).parent
# what serves or flies on fixed SITL ports: the harness on given numbers, a server, a
# number held by hand; and an `ft-sitl sitl` command (an argument list) without
# `--instance auto`, which serves the number it is given or 0
FIXED_USE = re.compile(r"\brunning_sitl\(|SitlServer\(|instances_held\(|base_instance=\d")
SITL_ARGV = re.compile(r"[\"']sitl[\"']([^\]]*)\]")
AUTO = re.compile(r"[\"']--instance[\"'],\s*[\"']auto[\"']")


def uses_fixed_ports(text: str) -> bool:
    return bool(FIXED_USE.search(text)) or any(
        not AUTO.search(m.group(1)) for m in SITL_ARGV.finditer(text))


def test_files_are_grouped_whole_and_fixed_port_files_together():
    assert group_of("tests/mavlink/test_orbit.py::test_x") == FIXED_PORTS_GROUP
    assert group_of("tests/wire/test_wire_trials.py::test_y[a::b]") == FIXED_PORTS_GROUP
    assert group_of("tests/cli/test_cli.py::test_z") == FIXED_PORTS_GROUP
    assert group_of("tests/cli/test_cli_scenarios.py::test_z") == "tests/cli/test_cli_scenarios.py"
    # the ArduCopter face's files take free instance numbers: each is a unit of its own
    assert group_of("tests/mavlink/test_ardupilot_modes.py::test_m") == \
        "tests/mavlink/test_ardupilot_modes.py"
    assert group_of("tests/wire/test_ardupilot_wire.py::test_w") == \
        "tests/wire/test_ardupilot_wire.py"
    assert group_of("tests/physics/test_motor.py::test_a[1]") == "tests/physics/test_motor.py"


class _Worker:
    """What xdist's scheduler sees of a worker: it is sent indices into the collection."""

    def __init__(self, name: str):
        self.gateway = SimpleNamespace(id=name)
        self.shutting_down = False
        self.queue: list[int] = []

    def send_runtest_some(self, indices):
        self.queue.extend(indices)

    def shutdown(self):
        self.shutting_down = True


def test_the_installed_xdist_schedules_by_our_groups():
    """The scheduler the conftest hook makes, driven as xdist's controller drives it (two
    workers, tests reported done one at a time): it overrides a private method of xdist's,
    so this fails if a pytest-xdist release stops calling it or schedules otherwise."""
    collection = [
        "tests/mavlink/test_orbit.py::test_a", "tests/mavlink/test_orbit.py::test_b",
        "tests/physics/test_motor.py::test_c[1]", "tests/physics/test_motor.py::test_c[2]",
        "tests/wire/test_wire_trials.py::test_d[x::y]",
        "tests/scenarios/test_io.py::test_e", "tests/scenarios/test_io.py::test_f",
        "tests/cli/test_cli.py::test_g", "tests/cli/test_cli_scenarios.py::test_h",
        "tests/bus/test_codec.py::test_i", "tests/missions/test_axes.py::test_j",
        "tests/bus/test_codec.py::test_k",
        "tests/mavlink/test_ardupilot_face.py::test_l",
    ] + [f"tests/scenarios/test_families.py::test_m[{k}]" for k in range(8)]
    config = SimpleNamespace(getvalue=lambda name: ["2*popen"] if name == "tx" else None,
                             option=SimpleNamespace(loadscopereorder=True))
    sched = pytest_xdist_make_scheduler(config, None)
    workers = [_Worker("gw0"), _Worker("gw1")]
    for w in workers:
        sched.add_node(w)
    for w in workers:
        sched.add_node_collection(w, collection)
    sched.schedule()
    # the group is handed out first, though a file has more tests (xdist's own order)
    assert collection[workers[0].queue[0]].startswith("tests/mavlink/test_orbit.py")
    ran: dict[str, str] = {}
    while any(w.queue for w in workers):
        for w in workers:
            if w.queue:
                i = w.queue.pop(0)
                ran[collection[i]] = w.gateway.id
                sched.mark_test_complete(w, i)
    assert sorted(ran) == sorted(collection) and sched.tests_finished
    by_group: dict[str, set] = {}
    for nodeid, worker in ran.items():
        by_group.setdefault(group_of(nodeid), set()).add(worker)
    assert all(len(ws) == 1 for ws in by_group.values()), by_group
    fixed = {n for n in collection if group_of(n) == FIXED_PORTS_GROUP}
    assert len(fixed) == 4 and len({ran[n] for n in fixed}) == 1
    assert set(ran.values()) == {"gw0", "gw1"}  # and it is a parallel run


def test_the_fixed_port_uses_are_recognised():
    assert uses_fixed_ports('with running_sitl(speed_factor=2.0) as server:')
    assert uses_fixed_ports('[EXE, "sitl", "--instance", str(inst), "--duration", "1"]')
    assert uses_fixed_ports("[EXE, 'sitl', '--instances', '2', '--json']")  # (instance 0)
    assert uses_fixed_ports("with instances_held(BASE, 2):")
    assert not uses_fixed_ports('with free_ardupilot_sitl() as (server, k):')
    assert not uses_fixed_ports('[sys.executable, "-m", "ft_sitl", "sitl", "--autopilot",\n'
                                '  "ardupilot", "--instance",\n  "auto", "--no-mqtt"]')
    # what the listed files do is recognised as such: each check can fail
    for rel in ("tests/cli/test_cli.py", "tests/mavlink/test_orbit.py",
                "tests/wire/test_movers_wire.py", "tests/wire/test_instances.py"):
        assert uses_fixed_ports((TESTS.parent / rel).read_text(encoding="utf-8")), rel


def test_every_file_on_fixed_ports_is_in_the_group():
    outside = []
    for path in sorted(TESTS.rglob("*.py")):
        rel = path.relative_to(TESTS.parent).as_posix()
        if group_of(rel) == FIXED_PORTS_GROUP or path.name in ("conftest.py",
                                                               "test_parallel.py"):
            continue
        if uses_fixed_ports(path.read_text(encoding="utf-8")):
            outside.append(rel)
    assert not outside, f"serve on the SITL's fixed ports outside the group: {outside}"
    assert all((TESTS.parent / rel).is_file() for rel in ALLOCATED), ALLOCATED
