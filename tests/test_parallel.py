"""The suite's parallel run (tests/conftest.py): the files that use the SITL's fixed MAVLink
ports share one xdist worker, every other file is run whole by one."""

import re
from pathlib import Path

from xdist.scheduler import LoadScopeScheduling

from .conftest import FIXED_PORTS, FIXED_PORTS_GROUP, group_of

TESTS = Path(__file__).parent
# what serves or flies on fixed SITL ports: the harness, a server, an `ft-sitl sitl` process
USES_FIXED_PORTS = re.compile(r"running_sitl|SitlServer\(|[\"']sitl[\"']")


def test_files_are_grouped_whole_and_fixed_port_files_together():
    assert group_of("tests/mavlink/test_orbit.py::test_x") == FIXED_PORTS_GROUP
    assert group_of("tests/wire/test_wire_trials.py::test_y[a::b]") == FIXED_PORTS_GROUP
    assert group_of("tests/cli/test_cli.py::test_z") == FIXED_PORTS_GROUP
    assert group_of("tests/cli/test_cli_scenarios.py::test_z") == "tests/cli/test_cli_scenarios.py"
    assert group_of("tests/physics/test_motor.py::test_a[1]") == "tests/physics/test_motor.py"
    # the scheduler hook overrides this method of xdist's: it must still be there
    assert callable(getattr(LoadScopeScheduling, "_split_scope", None))


def test_every_file_on_fixed_ports_is_in_the_group():
    outside = []
    for path in sorted(TESTS.rglob("*.py")):
        rel = path.relative_to(TESTS.parent).as_posix()
        if rel.startswith(FIXED_PORTS) or path.name in ("conftest.py", "test_parallel.py"):
            continue
        if USES_FIXED_PORTS.search(path.read_text(encoding="utf-8")):
            outside.append(rel)
    assert not outside, f"serve on the SITL's fixed ports outside {FIXED_PORTS}: {outside}"
