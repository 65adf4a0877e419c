"""The pytest plugin (entry point ``pytest11: ft_sitl``): fixtures that serve simulated PX4
vehicles to a test, and a failed test's flight attached to its report. Guide:
docs/testing.md.

Fixtures:

- ``ft_sitl_vehicle``: one vehicle for the test (:class:`~ft_sitl_pytest.vehicle.Vehicle`:
  its MAVSDK and pymavlink URLs, sysid, instance, ports).
- ``ft_sitl_fleet``: several vehicles of one ``ft-sitl sitl`` (a list of Vehicle; 2 unless
  ``vehicles=N``).
- ``ft_sitl_factory`` (session): ``ft_sitl_factory.serve(vehicles=1, name="sitl",
  **options)`` starts vehicles for any scope (a module fixture that shares one) and
  returns the :class:`~ft_sitl_pytest.vehicle.Sitl`; stop it (or use it as a context
  manager), or it is stopped at the end of the session.

Options (ft_sitl_pytest.options.OPTIONS) come from ``@pytest.mark.ft_sitl(...)`` on the
test, its class or module (the closest wins), then from indirect parametrisation
(``@pytest.mark.parametrize("ft_sitl_vehicle", [{...}], indirect=True)``).
"""

from __future__ import annotations

import argparse
import math
import re
import shutil
from contextlib import contextmanager
from pathlib import Path

import pytest

from ft_sitl_pytest.options import OPTIONS, OptionError, sitl_arguments, start_timeout
from ft_sitl_pytest.vehicle import Sitl, SitlStartError, log_tail, serve

MARKER = "ft_sitl"
DEFAULT_START_TIMEOUT_S = 300.0
#: the name of the report section that lists a failed test's flight files
SECTION = "ft-sitl flight"

_OWNED = pytest.StashKey[list]()  # the Sitl processes the test's own fixtures started
_ATTACHED = pytest.StashKey[set]()  # (ids of) those already attached to a report
_FAILED = pytest.StashKey[bool]()


def _seconds(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number of seconds") from None
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"{text} must be a number of seconds > 0")
    return value


def pytest_addoption(parser):
    group = parser.getgroup("ft-sitl", "ft-sitl simulated vehicles (docs/testing.md)")
    group.addoption("--ft-sitl-logs", metavar="DIR", type=Path, default=None,
                    help="directory for each test's vehicle files (telemetry log, process "
                         "log, trajectory plot); default: ft-sitl/ in pytest's basetemp")
    group.addoption("--ft-sitl-keep-logs", action="store_true",
                    help="keep the vehicle files of passing tests too (default: failing "
                         "tests' only)")
    group.addoption("--ft-sitl-start-timeout", type=_seconds,
                    default=DEFAULT_START_TIMEOUT_S, metavar="S",
                    help="wall seconds a vehicle may take to start serving (default "
                         f"{DEFAULT_START_TIMEOUT_S:g}: the first start after an install "
                         "compiles the simulator)")


def pytest_configure(config):
    config.addinivalue_line(
        "markers", f"{MARKER}(**options): the options of the test's ft_sitl_vehicle and "
        f"ft_sitl_fleet ({', '.join(OPTIONS)}; docs/testing.md)")


class SitlFactory:
    """Starts ``ft-sitl sitl`` processes, each in a directory of its own under ``root``."""

    def __init__(self, root: Path, timeout_s: float, keep: bool):
        self.root = root
        self.timeout_s = timeout_s
        self.keep = keep
        #: the processes started and not yet stopped through a fixture
        self.live: list[Sitl] = []

    def serve(self, vehicles: int = 1, name: str = "sitl", **options) -> Sitl:
        """Vehicles serving (see the module's options); raises OptionError or
        SitlStartError naming what went wrong."""
        where = f"ft-sitl vehicles {name!r}"
        options = {"vehicles": vehicles, **options}
        argv = sitl_arguments(options, where)
        timeout = start_timeout(options, self.timeout_s, where)
        sitl = serve(argv, self._new_dir(name), timeout, where)
        self.live.append(sitl)
        return sitl

    def _new_dir(self, name: str) -> Path:
        safe = re.sub(r"[^A-Za-z0-9_.-]+", "_", name).strip("_")[-120:] or "sitl"
        self.root.mkdir(parents=True, exist_ok=True)
        k = 1
        while True:  # mkdir is atomic: xdist workers sharing --ft-sitl-logs never collide
            path = self.root / (safe if k == 1 else f"{safe}-{k}")
            try:
                path.mkdir()
                return path
            except FileExistsError:
                k += 1

    def stop_all(self) -> None:
        for sitl in self.live:
            sitl.stop()
        self.live.clear()


@pytest.fixture(scope="session")
def ft_sitl_factory(request, tmp_path_factory) -> SitlFactory:
    """Starts simulated vehicles for any scope: ``ft_sitl_factory.serve(vehicles=1,
    name="sitl", **options)`` returns a running Sitl (``.vehicles``, ``.tlog``,
    ``.stop()``)."""
    cfg = request.config
    root = cfg.getoption("ft_sitl_logs") or tmp_path_factory.getbasetemp() / "ft-sitl"
    factory = SitlFactory(Path(root).resolve(), cfg.getoption("ft_sitl_start_timeout"),
                          cfg.getoption("ft_sitl_keep_logs"))
    yield factory
    factory.stop_all()


def _options(request, fixture: str) -> dict:
    """The test's options: its markers (the closest last, so it wins), then its param."""
    options: dict = {}
    for mark in reversed(list(request.node.iter_markers(MARKER))):
        if mark.args:
            raise OptionError(f"@pytest.mark.{MARKER}{mark.args!r}: options are keywords "
                              f"(platform=..., speed_factor=...)")
        options.update(mark.kwargs)
    param = getattr(request, "param", None)
    if param is not None:
        if not isinstance(param, dict):
            raise OptionError(f"{fixture}: an indirect parameter must be a dict of "
                              f"options, not {param!r}")
        options.update(param)
    return options


@contextmanager
def _served(request, factory: SitlFactory, fixture: str, vehicles: int):
    problem = None
    try:
        options = _options(request, fixture)
        options.setdefault("vehicles", vehicles)
        if fixture == "ft_sitl_vehicle" and options["vehicles"] != 1:
            raise OptionError(f"it serves one vehicle, not vehicles="
                              f"{options['vehicles']!r}: use ft_sitl_fleet")
        sitl = factory.serve(name=request.node.nodeid, **options)
    except (OptionError, SitlStartError) as exc:
        problem = f"{fixture}: {exc}"
    if problem is not None:  # (outside the except: the error alone, not a chain)
        pytest.fail(problem, pytrace=False)
    request.node.stash.setdefault(_OWNED, []).append(sitl)
    try:
        yield sitl
    finally:
        sitl.stop()
        factory.live.remove(sitl)
        failed = request.node.stash.get(_FAILED, False) or sitl.exited_early is not None
        if not failed and not factory.keep:
            shutil.rmtree(sitl.log_dir, ignore_errors=True)
    if sitl.exited_early is not None:
        pytest.fail(f"{fixture}: the ft-sitl sitl process ended by itself during the test "
                    f"(status {sitl.exited_early}); its log {sitl.log}:\n"
                    f"{log_tail(sitl.log)}", pytrace=False)


@pytest.fixture
def ft_sitl_vehicle(request, ft_sitl_factory):
    """One simulated PX4 vehicle for the test (a Vehicle: mavsdk_url, pymavlink_url,
    sysid, instance, ports), on free instance numbers; options from
    ``@pytest.mark.ft_sitl(...)`` or indirect parametrisation."""
    with _served(request, ft_sitl_factory, "ft_sitl_vehicle", 1) as sitl:
        yield sitl.vehicles[0]


@pytest.fixture
def ft_sitl_fleet(request, ft_sitl_factory):
    """Several simulated vehicles of one ft-sitl sitl (a list of Vehicle, sysids 1..N on
    consecutive instance numbers; ``vehicles=N``, default 2)."""
    with _served(request, ft_sitl_factory, "ft_sitl_fleet", 2) as sitl:
        yield list(sitl.vehicles)


@pytest.hookimpl(wrapper=True)
def pytest_runtest_makereport(item, call):
    report = yield
    if report.failed and report.when in ("setup", "call"):
        item.stash[_FAILED] = True
        owned = [s for s in item.stash.get(_OWNED, [])
                 if id(s) not in item.stash.setdefault(_ATTACHED, set())]
        if owned:
            _attach(item, report, owned)
    return report


def _attach(item, report, sitls: list[Sitl]) -> None:
    """Stop the test's vehicles (closing their logs), plot their flights, and name the files
    in the report (a section, and user_properties for JUnit XML)."""
    from ft_sitl_pytest.flight_plot import plot_flight  # matplotlib: only for a failure

    lines = []
    for sitl in sitls:
        item.stash[_ATTACHED].add(id(sitl))
        sitl.stop()
        png = sitl.log_dir / "trajectory.png"
        try:
            summary = plot_flight(sitl.tlog, png, item.nodeid)
        except Exception as exc:  # noqa: BLE001 - the report must still show the failure
            summary, png = [f"(no trajectory plot: {type(exc).__name__}: {exc})"], None
        size = sitl.tlog.stat().st_size if sitl.tlog.exists() else 0
        lines += [f"vehicle files in {sitl.log_dir}",
                  f"  telemetry log:   {sitl.tlog} ({size / 1024:.0f} kB)"]
        if png is not None:
            lines.append(f"  trajectory plot: {png}")
        lines += [f"  process log:     {sitl.log}",
                  f"  serve again:     {sitl.replay_command()}",
                  *(f"  {s}" for s in summary)]
        props = [("ft_sitl_tlog", str(sitl.tlog)), ("ft_sitl_log", str(sitl.log))]
        if png is not None:
            props.append(("ft_sitl_trajectory", str(png)))
        item.user_properties.extend(props)  # (the teardown report, which JUnit XML reads)
        report.user_properties.extend(props)
    report.sections.append((SECTION, "\n".join(lines)))
