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

# Parallel runs (pytest-xdist; pyproject's addopts run `-n 2`, `-n 0` runs in this process
# alone). Each test file is run whole by one worker, so a file's module fixtures are built
# once. The files that serve or fly on the SITL's fixed MAVLink ports (an `ft-sitl sitl`
# process, a server on a given instance, clients listening on 14540 + N) go to one worker
# together: two of them at once would take the same ports. Trials over MAVLink pick free
# instance numbers under a machine-wide lock (ft_sitl.mavlink.instances) and the bridge
# tests use instance numbers of their own file, so those need nothing more.
#
# This overrides a private method of xdist's (LoadScopeScheduling._split_scope), which is
# why pyproject pins pytest-xdist below 4; tests/test_parallel.py drives the scheduler
# on a made-up collection and fails if the grouping stops happening. What xdist supports
# does not do it (tried 2026-12-07 with pytest 9.2.0 and pytest-xdist 3.8.0, the newest
# on PyPI): `--dist loadgroup` with `@pytest.mark.xdist_group(name=...)` (also added from
# a collection hook) groups nothing: xdist marks a test's group by assigning
# `item._nodeid`, which pytest 9.2 no longer reads (node ids are `Node._id`), so the
# grouped tests of four files were spread over both workers like ungrouped ones
# (pytest-xdist issue 1386; the fix, PR 1388, is unreleased); and it would run every
# ungrouped test on its own, not a file whole. `--dist loadfile` keeps a file whole but
# puts different files on different workers. `--dist loadscope` is by file or class,
# `worksteal` and `load` by test. Relying on the ports' lock instead is not enough: trials
# and the harness wait for a held number, but `ft-sitl sitl` (tests/cli, tests/wire)
# refuses one, so it would fail while the other worker's harness holds it.
FIXED_PORTS_GROUP = "sitl-ports"
FIXED_PORTS = ("tests/mavlink/", "tests/wire/", "tests/cli/test_cli.py",
               "tests/missions/test_axes.py", "tests/scenarios/test_movers_spec.py")


def group_of(nodeid: str) -> str:
    """The unit a worker runs whole: the test's file, or the fixed-ports group."""
    path = nodeid.split("::", 1)[0]
    return FIXED_PORTS_GROUP if path.startswith(FIXED_PORTS) else path


def pytest_xdist_make_scheduler(config, log):
    from xdist.scheduler import LoadScopeScheduling

    class ByGroup(LoadScopeScheduling):
        def _split_scope(self, nodeid: str) -> str:
            return group_of(nodeid)

    return ByGroup(config, log)
