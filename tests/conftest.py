# ft_sitl first, before anything loads numpy: its import pins the BLAS settings trial
# results depend on (ft_sitl.numeric_env), so trials flown in this process match those of
# the ft-sitl command and the committed results
import ft_sitl  # noqa: F401, I001

import os
from pathlib import Path

import pytest

# The team's shared material (the paper's tables, the NavRL checkpoint) sits beside the
# repository as ../shared; FT_SITL_SHARED points a clone elsewhere at it.
SHARED_ENV = "FT_SITL_SHARED"
SHARED = Path(os.environ.get(SHARED_ENV) or Path(__file__).resolve().parents[1].parent / "shared")
TABLE1 = SHARED / "spec" / "platforms_table1.csv"


@pytest.fixture(scope="session")
def table1_rows():
    """The paper's Table 1, as shipped in shared/spec (the source the catalog was built from)."""
    import csv

    if not TABLE1.exists():
        pytest.fail(f"{TABLE1} is missing: the tests check the catalog against the paper's "
                    f"table (set {SHARED_ENV} to the directory holding spec/)")
    with open(TABLE1, newline="", encoding="utf-8") as fh:
        return list(csv.DictReader(fh))


NAVRL_CHECKPOINT = SHARED / "data" / "navrl" / "navrl_checkpoint.pt"


@pytest.fixture(scope="session")
def navrl_checkpoint() -> Path:
    """The NavRL authors' released checkpoint, as test data (ft-sitl does not ship it)."""
    if not NAVRL_CHECKPOINT.is_file():
        pytest.fail(f"{NAVRL_CHECKPOINT} is missing: the NavRL tests read the released "
                    f"checkpoint from the team's shared data (set {SHARED_ENV} to the directory "
                    "holding data/navrl/)")
    return NAVRL_CHECKPOINT


# The lanes (tests/lanes.py): the marks `e2e` and `slow`, the unit lane
# `-m "not e2e and not slow"`, and the guard that fails a test without the `e2e` mark that
# opens a network socket or starts a process.
from .lanes import pytest_runtest_call, pytest_runtest_setup  # noqa: E402, F401, I001

# Parallel runs (pytest-xdist; pyproject's addopts run `-n 3`, `-n 0` runs in this process
# alone: three workers on two cores, since the fixed-ports group below waits on the wall
# clock most of the time and the other two workers fill the cores meanwhile: 1,018 s of
# tests against 1,254 s on two, clean clones, 2026-12-07). Each test file is run whole by
# one worker, so a file's module fixtures are built once. The files that serve or fly on
# the SITL's fixed MAVLink ports (an `ft-sitl sitl` process on a given instance or its
# default 0, a server on a given instance: the harness's running_sitl, clients listening
# on 14540 + N) go to one worker together: two of them at once would take the same ports.
# That is every file under FIXED_PORTS but those in ALLOCATED, which take their instance
# numbers only through the machine-wide allocation (ft_sitl.mavlink.instances: the
# ArduCopter face's harness free_ardupilot_sitl and ardupilot_sitl_process, `--instance
# auto`, wire trials' InstanceLock) or open no port at all, so they run on either worker
# like any other file (a new file under FIXED_PORTS joins the group until it is listed).
# tests/test_parallel.py fails if a file outside the group shows a fixed-port use. The
# group is handed out first: it is the longest unit (38 % of the test time before these
# files left it, 22 % after, in a run under load, 2026-12-07; more on an idle machine,
# where its wall-paced MAVLink flights keep their time and the rest runs faster), and
# xdist's own order (most tests first) could leave it to start late and end last.
#
# This overrides private methods of xdist's (LoadScopeScheduling._split_scope and
# _assign_work_unit), which is why pyproject pins pytest-xdist below 4;
# tests/test_parallel.py drives the scheduler on a made-up collection and fails if the
# grouping or the group's first place stops happening. What xdist supports does not do it
# (tried 2026-12-07 with pytest 9.2.0 and pytest-xdist 3.8.0, the newest on PyPI): `--dist
# loadgroup` with `@pytest.mark.xdist_group(name=...)` (also added from a collection hook)
# groups nothing: xdist marks a test's group by assigning `item._nodeid`, which pytest 9.2
# no longer reads (node ids are `Node._id`), so the grouped tests of four files were
# spread over both workers like ungrouped ones (pytest-xdist issue 1386; the fix, PR 1388,
# is unreleased); and it would run every ungrouped test on its own, not a file whole.
# `--dist loadfile` keeps a file whole but puts different files on different workers.
# `--dist loadscope` is by file or class, `worksteal` and `load` by test. Relying on the
# ports' lock instead is not enough: trials and the harness wait for a held number, but
# `ft-sitl sitl` (tests/cli, tests/wire) refuses one, so it would fail while the other
# worker's harness holds it.
FIXED_PORTS_GROUP = "sitl-ports"
FIXED_PORTS = ("tests/mavlink/", "tests/wire/", "tests/cli/test_cli.py",
               "tests/scenarios/test_movers_spec.py")
ALLOCATED = (
    "tests/mavlink/test_ardupilot_dronekit.py", "tests/mavlink/test_ardupilot_face.py",
    "tests/mavlink/test_ardupilot_fence_rally.py", "tests/mavlink/test_ardupilot_mavproxy.py",
    "tests/mavlink/test_ardupilot_mavsdk.py", "tests/mavlink/test_ardupilot_modes.py",
    "tests/mavlink/test_ardupilot_params.py", "tests/mavlink/test_ardupilot_parity.py",
    "tests/mavlink/test_ardupilot_robustness.py", "tests/mavlink/test_ardupilot_streams.py",
    "tests/mavlink/test_ardupilot_waypoints.py",
    "tests/wire/test_ardupilot_wire.py", "tests/wire/test_lockstep_order.py",
    "tests/wire/test_convert_task.py",
)


def group_of(nodeid: str) -> str:
    """The unit a worker runs whole: the test's file, or the fixed-ports group."""
    path = nodeid.split("::", 1)[0]
    if path.startswith(FIXED_PORTS) and path not in ALLOCATED:
        return FIXED_PORTS_GROUP
    return path


def pytest_xdist_make_scheduler(config, log):
    from xdist.scheduler import LoadScopeScheduling

    class ByGroup(LoadScopeScheduling):
        def _split_scope(self, nodeid: str) -> str:
            return group_of(nodeid)

        def _assign_work_unit(self, node) -> None:
            if FIXED_PORTS_GROUP in self.workqueue:  # (the longest: first)
                self.workqueue.move_to_end(FIXED_PORTS_GROUP, last=False)
            super()._assign_work_unit(node)

    return ByGroup(config, log)
