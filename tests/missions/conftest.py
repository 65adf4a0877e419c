"""Shared fixtures of the mission tests: a small user scenario and a plug-in distribution.

``yard``: a 10 x 20 m flight volume (ceiling 4 m) with one wall across the straight
start -> goal line and a way round it on either side. Its collision grid builds in a
fraction of a second and a trial in it is short, so most trial and campaign tests fly
there.

``plugin_dir``: a directory holding an importable package of test navigators and the
``*.dist-info`` metadata that registers them in the ``ft_sitl.navigators`` entry point
group, as ``pip install`` would. Put it on ``sys.path`` (the ``plugins`` fixture) or on
``PYTHONPATH`` (subprocesses and the campaign's spawned workers) and
``importlib.metadata`` finds the entry points. It also registers one broken entry point.
"""

import json
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
import trimesh

PLATFORM = "1.00kg-SunnySky"
EXE = shutil.which("ft-sitl", path=str(Path(sys.executable).parent))

# the yard: start, goal, the wall across the line between them
YARD_START = (5.0, 2.0, 1.5)
YARD_GOAL = (5.0, 18.0, 1.5)
YARD_WALL = ((2.0, 9.8, 0.0), (8.0, 10.2, 3.0))

PLUGIN_PACKAGE = "ftnav_testplugins"
PLUGIN_SOURCE = '''\
"""Navigators of the ft-sitl mission tests, registered through a real entry point."""

import os
import signal
import time

from numba import njit

from ft_sitl.autopilot.setpoints import Setpoint
from ft_sitl.navigation.base import Navigator
from ft_sitl.schema import Param, Schema


class Hover(Navigator):
    """Hover at the start waypoint (times out); optionally sleep in reset (wall clock)."""

    name = "t_hover"
    schema = Schema((Param("sleep_s", 0.0, "s", (0.0, 600.0), doc="sleep in reset"),))

    def __init__(self, **params):
        super().__init__(**params)
        self.sleep_s = float(self.settings["sleep_s"])

    def reset(self, task):
        super().reset(task)
        time.sleep(self.sleep_s)

    def step(self, obs):
        return Setpoint.position(self.task.start)


class Killer(Navigator):
    """Kill its own process with SIGKILL 0.2 s into the navigation phase."""

    name = "t_killer"

    def step(self, obs):
        if obs.time_s >= 0.2:
            os.kill(os.getpid(), signal.SIGKILL)
        return Setpoint.position(self.task.start)


class Spin(Navigator):
    """Enter a compiled loop that does not return in any test's lifetime (about 10^12
    multiply-adds), 0.2 s into the navigation phase: no signal handler runs meanwhile."""

    name = "t_spin"

    def step(self, obs):
        if obs.time_s >= 0.2:
            _spin(10 ** 12)
        return Setpoint.position(self.task.start)


@njit(cache=False)
def _spin(n):
    acc = 0.0
    for i in range(n):
        acc = acc * 0.999999 + 1.0  # a recurrence: no closed form, cannot be optimised out
    return acc


NOT_A_NAVIGATOR = 42
'''
ENTRY_POINTS = f"""\
[ft_sitl.navigators]
t_hover = {PLUGIN_PACKAGE}:Hover
t_killer = {PLUGIN_PACKAGE}:Killer
t_spin = {PLUGIN_PACKAGE}:Spin
t_broken = {PLUGIN_PACKAGE}_missing.nav:Broken
t_notnav = {PLUGIN_PACKAGE}:NOT_A_NAVIGATOR
"""


def write_yard(directory: Path, name: str = "yard", wall=YARD_WALL) -> Path:
    """Write the yard's mesh and scenario spec into directory; the spec's path."""
    directory.mkdir(parents=True, exist_ok=True)
    trimesh.creation.box(bounds=[wall[0], wall[1]]).export(directory / f"{name}.ply")
    spec = directory / f"{name}.yaml"
    spec.write_text(f"name: {name}\nmesh: {name}.ply\nstart: {list(YARD_START)}\n"
                    f"goal: {list(YARD_GOAL)}\nbounds_min: [0, 0, 0]\n"
                    "bounds_max: [10, 20, 4]\n")
    return spec


@pytest.fixture(scope="session")
def yard(tmp_path_factory) -> Path:
    """The yard's scenario spec file (a user scenario, family 'yard')."""
    return write_yard(tmp_path_factory.mktemp("yard"))


@pytest.fixture(scope="session")
def plugin_dir(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("plugins")
    pkg = root / PLUGIN_PACKAGE
    pkg.mkdir()
    (pkg / "__init__.py").write_text(PLUGIN_SOURCE)
    info = root / f"{PLUGIN_PACKAGE}-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(
        f"Metadata-Version: 2.1\nName: {PLUGIN_PACKAGE}\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(ENTRY_POINTS)
    return root


@pytest.fixture
def plugins(plugin_dir, monkeypatch) -> Path:
    """The test navigators installed for this test only (on sys.path)."""
    monkeypatch.syspath_prepend(str(plugin_dir))
    return plugin_dir


@pytest.fixture(scope="session")
def cli_env(plugin_dir) -> dict:
    """Environment of an ``ft-sitl`` subprocess that sees the test navigators (its
    spawned workers inherit it)."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(
        p for p in (str(plugin_dir), env.get("PYTHONPATH", "")) if p)
    env["OMP_NUM_THREADS"] = "1"
    return env


def run_exe(*args, env=None, timeout=180) -> subprocess.CompletedProcess:
    """The installed ``ft-sitl`` script, to completion."""
    assert EXE, "the ft-sitl console script is not installed next to this Python"
    return subprocess.run([EXE, *map(str, args)], capture_output=True, text=True,
                          timeout=timeout, env=env)


def read_jsonl(path: Path) -> list[dict]:
    """Every line of a trials.jsonl, each of which must be a complete JSON row."""
    raw = path.read_bytes()
    assert raw.endswith(b"\n"), f"{path} does not end with a complete line"
    return [json.loads(line) for line in raw.decode().splitlines()]


def campaign_file(directory: Path, name: str, text: str) -> Path:
    path = directory / name
    path.write_text(textwrap.dedent(text))
    return path
