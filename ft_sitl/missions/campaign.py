"""Campaigns: the algorithm x platform x scenario x trial matrix, run and resumed.

A campaign file (TOML or YAML) names what to run; every key is optional except
``algorithms``::

    name = "my-campaign"
    trials = 10                      # per (algorithm, platform, scenario family)
    seed = 0                         # trial seeds derive from it
    scenario_seed = 0                # seed of the scenario configurations
    platforms = ["real"]             # names, categories (real, virtual, user) or "all"
    platform_files = ["mine.toml"]   # user platforms (relative to this file)
    scenarios = "all"                # families (paper names work), {family, indices},
                                     # {file = "yard.yaml"} (a user scenario), or "all"
    indices = "all"                  # default configurations of each family (1..10)
    physics_hz = 1000

    [[algorithms]]                   # or: algorithms = "all" / ["straight", ...]
    name = "straight"                # a registered navigator
    label = "straight-3"             # optional: its name in the results
    params = { speed_m_s = 3.0 }

    [limits]                         # the protocol's defaults
    max_speed_m_s = 4.0
    timeout_s = 90.0
    goal_radius_m = 2.0
    hold_s = 3.0

    [weights]                        # composite score (paper defaults)
    scenarios = { classic = 1.2, theoretical = 1.0 }
    platforms = { real = 1.5, virtual = 1.0 }
    beta = 0.3

Trial ``t`` (0-based) of a combination flies configuration ``indices[t % len(indices)]``,
so 10 trials over the ten configurations fly each once, as in the paper. Its seed is
derived from the campaign seed, the combination and ``t``.

Running: :func:`run_campaign` hands trials, grouped by scenario configuration (a worker
builds each scenario's collision grid once), to an :class:`Executor`: in-process
(``workers=1``) or a pool of worker processes; a distributed executor only has to
implement :meth:`Executor.imap`. Each finished trial is written to the
:class:`~ft_sitl.missions.store.ResultStore` at once; a rerun of the same campaign into
the same directory skips finished trials.
"""

from __future__ import annotations

import difflib
import hashlib
import math
import os
import time
import tomllib
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

from ft_sitl import __version__
from ft_sitl.missions.protocol import failed_row
from ft_sitl.missions.resources import RESOURCES
from ft_sitl.missions.results import Outcome
from ft_sitl.missions.spec import TrialSpec, platform_for
from ft_sitl.missions.trial import run_trial
from ft_sitl.missions.trial_wire import run_trial_wire, worker_bus
from ft_sitl.missions.watchdog import wall_budget_from_env
from ft_sitl.navigation.base import Limits

PRESETS = ("quick", "paper")
TOP_KEYS = ("name", "trials", "seed", "scenario_seed", "platforms", "platform_files",
            "scenarios", "indices", "physics_hz", "algorithms", "limits", "weights",
            "description")
CHUNK_MAX = 40
#: the workers' shared distance grids, inside the output directory while a run lasts (a
#: killed run leaves at most trial.GRID_CACHE_KEEP grids there; the next run reuses them
#: and removes the directory when it ends)
GRID_CACHE_DIR = ".grid-cache"


class CampaignError(ValueError):
    """A campaign file or request is invalid; the message names the file and the key."""


# --- reading a campaign file ----------------------------------------------------------------
def _read(path: Path) -> dict:
    try:
        text = path.read_text()
    except FileNotFoundError:
        raise CampaignError(f"{path}: no such campaign file (presets: "
                            f"{', '.join(PRESETS)})") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise CampaignError(f"{path}: cannot read it ({exc})") from None
    suffix = path.suffix.lower()
    if suffix == ".toml":
        try:
            doc = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise CampaignError(f"{path}: TOML syntax error: {exc}") from None
    elif suffix in (".yaml", ".yml"):
        import yaml

        try:
            doc = yaml.safe_load(text)
        except yaml.YAMLError as exc:
            mark = getattr(exc, "problem_mark", None)
            where = f" at line {mark.line + 1}" if mark is not None else ""
            raise CampaignError(f"{path}: YAML syntax error{where}: "
                                f"{getattr(exc, 'problem', exc)}") from None
    else:
        raise CampaignError(f"{path}: a campaign file must end in .toml, .yaml or .yml")
    if not isinstance(doc, dict):
        raise CampaignError(f"{path}: the campaign must be a table of keys, got "
                            f"{type(doc).__name__}")
    return doc


def preset_path(name: str) -> Path:
    return Path(str(resources.files("ft_sitl.missions") / "presets" / f"{name}.toml"))


def load_campaign(source: str | Path) -> Campaign:
    """A campaign from a file, or a preset by name (``quick``, ``paper``)."""
    text = str(source)
    path = Path(text)
    if text in PRESETS:  # a bare preset name (a campaign file always has a suffix)
        path = preset_path(text)
    return parse_campaign(_read(path), path)


def _unknown(where: str, key: str, allowed: Iterable[str]) -> CampaignError:
    close = difflib.get_close_matches(key, list(allowed), n=1)
    hint = f"; did you mean {close[0]!r}?" if close else ""
    return CampaignError(f"{where}: unknown key {key!r}{hint}")


def _int(where: str, v, lo: int = 0, hi: int | None = None) -> int:
    if isinstance(v, bool) or not isinstance(v, int) or v < lo or (hi is not None and v > hi):
        rng = f"{lo}..{hi}" if hi is not None else f">= {lo}"
        raise CampaignError(f"{where}: must be an integer {rng}, got {v!r}")
    return v


def _list(where: str, v) -> list:
    if isinstance(v, (str, dict)):
        return [v]
    if not isinstance(v, list) or not v:
        raise CampaignError(f"{where}: must be a non-empty list, got {v!r}")
    return v


@dataclass(frozen=True)
class AlgorithmEntry:
    name: str
    label: str
    params: dict


@dataclass(frozen=True)
class ScenarioEntry:
    family: str
    indices: tuple[int, ...]
    file: str | None = None


@dataclass
class Campaign:
    name: str
    algorithms: list[AlgorithmEntry]
    platforms: list  # Platform objects
    scenarios: list[ScenarioEntry]
    trials: int = 10
    seed: int = 0
    scenario_seed: int = 0
    limits: Limits = field(default_factory=Limits)
    weights: dict = field(default_factory=dict)
    physics_hz: int = 1000
    source: str = ""
    doc: dict = field(default_factory=dict)
    #: what "all" left out and why (e.g. a navigator without its model weights)
    notes: list[str] = field(default_factory=list)

    def spec_dict(self) -> dict:
        """The campaign as data: what resuming compares, what reports print."""
        return {
            "name": self.name, "trials": self.trials, "seed": self.seed,
            "scenario_seed": self.scenario_seed, "physics_hz": self.physics_hz,
            "algorithms": [{"name": a.name, "label": a.label, "params": a.params}
                           for a in self.algorithms],
            "platforms": [p.name for p in self.platforms],
            "scenarios": [{"family": s.family, "indices": list(s.indices),
                           **({"file": s.file} if s.file else {})} for s in self.scenarios],
            "limits": self.limits.as_dict(), "weights": self.weights,
        }

    def trial_specs(self) -> list[TrialSpec]:
        """Every trial of the matrix, grouped by scenario configuration."""
        out = []
        for sc in self.scenarios:
            for a in self.algorithms:
                for p in self.platforms:
                    for t in range(self.trials):
                        index = sc.indices[t % len(sc.indices)]
                        key = f"{self.seed}|{a.label}|{p.name}|{sc.family}|{t}".encode()
                        seed = int.from_bytes(hashlib.sha256(key).digest()[:4], "little")
                        out.append(TrialSpec(
                            algorithm=a.name, label=a.label, algorithm_params=a.params,
                            platform=p.name,
                            platform_def=p.physical_dict() if p.category == "user" else None,
                            family=sc.family, scenario_index=index,
                            scenario_seed=self.scenario_seed, scenario_file=sc.file,
                            trial=t, seed=seed, limits=self.limits, campaign=self.name,
                            physics_hz=self.physics_hz))
        out.sort(key=lambda s: (s.scenario_file or "", s.family, s.scenario_index))
        return out


def parse_campaign(doc: dict, path: Path | None = None) -> Campaign:
    where = str(path) if path is not None else "campaign"
    base = path.parent if path is not None else Path(".")
    for k in doc:
        if k not in TOP_KEYS:
            raise _unknown(where, k, TOP_KEYS)
    if "algorithms" not in doc:
        raise CampaignError(f"{where}: missing key 'algorithms' (which navigators to run)")
    name = doc.get("name", path.stem if path is not None else "campaign")
    if not isinstance(name, str) or not name:
        raise CampaignError(f"{where}: name: must be a non-empty string")
    trials = _int(f"{where}: trials", doc.get("trials", 10), 1, 10_000)
    seed = _int(f"{where}: seed", doc.get("seed", 0))
    scenario_seed = _int(f"{where}: scenario_seed", doc.get("scenario_seed", 0))
    physics_hz = _int(f"{where}: physics_hz", doc.get("physics_hz", 1000), 100, 10_000)
    if 1_000_000 % physics_hz:
        raise CampaignError(f"{where}: physics_hz: {physics_hz} must divide 1,000,000")
    limits_doc = doc.get("limits", {})
    if not isinstance(limits_doc, dict):
        raise CampaignError(f"{where}: limits: must be a table")
    allowed = ("max_speed_m_s", "timeout_s", "goal_radius_m", "hold_s")
    for k in limits_doc:
        if k not in allowed:
            raise _unknown(f"{where}: limits", k, allowed)
    try:
        limits = Limits(**limits_doc)
    except ValueError as exc:
        raise CampaignError(f"{where}: {exc}") from None
    platforms = _platforms(where, doc.get("platforms", "all"), doc.get("platform_files", []),
                           base)
    scenarios = _scenarios(where, doc.get("scenarios", "all"), doc.get("indices", "all"), base)
    weights = _weights(where, doc.get("weights", {}))
    _check_weights(where, weights, platforms, scenarios)
    notes: list[str] = []
    return Campaign(
        name=name, algorithms=_algorithms(where, doc["algorithms"], notes), platforms=platforms,
        scenarios=scenarios, trials=trials, seed=seed, scenario_seed=scenario_seed,
        limits=limits, weights=weights, physics_hz=physics_hz,
        source=str(path) if path is not None else "", doc=doc, notes=notes)


def _check_weights(where: str, weights: dict, platforms, scenarios) -> None:
    """Refuse now what the score would refuse after every trial has flown."""
    from ft_sitl.missions import scoring
    from ft_sitl.scenarios.families import CATEGORY

    fam = {s.family: ("user" if s.file else CATEGORY.get(s.family, "user")) for s in scenarios}
    plat = {p.name: p.category for p in platforms}
    try:
        scoring._resolve_weights(weights.get("scenarios"), scoring.DEFAULT_SCENARIO_WEIGHTS,
                                 fam, fam, "weights.scenarios")
        scoring._resolve_weights(weights.get("platforms"), scoring.DEFAULT_PLATFORM_WEIGHTS,
                                 plat, plat, "weights.platforms")
    except ValueError as exc:
        raise CampaignError(f"{where}: {exc}") from None


def _algorithms(where: str, v, notes: list[str] | None = None) -> list[AlgorithmEntry]:
    from ft_sitl.navigation.registry import NavigatorError, available, create

    if v == "all":
        v = []
        for n, c in sorted(available().items()):
            why = c if isinstance(c, str) else c.unavailable()
            if why is None:
                v.append(n)
            elif notes is not None:
                notes.append(f"algorithms = \"all\" leaves out {n!r}: {why}")
    out, labels = [], set()
    for k, item in enumerate(_list(f"{where}: algorithms", v)):
        w = f"{where}: algorithms[{k}]"
        if isinstance(item, str):
            item = {"name": item}
        if not isinstance(item, dict):
            raise CampaignError(f"{w}: must be a navigator name or a table with 'name'")
        for key in item:
            if key not in ("name", "label", "params", "command"):
                raise _unknown(w, key, ("name", "label", "params", "command"))
        if "command" in item:
            out.append(_command_entry(w, item, labels))
            continue
        name = item.get("name")
        if not isinstance(name, str):
            raise CampaignError(f"{w}: missing 'name' (a registered navigator)")
        params = item.get("params", {})
        if not isinstance(params, dict):
            raise CampaignError(f"{w}: params: must be a table of parameters")
        try:
            create(name, params)  # validates the name and the parameters now
        except NavigatorError as exc:
            raise CampaignError(f"{w}: {exc}") from None
        label = item.get("label", name)
        if not isinstance(label, str) or not label:
            raise CampaignError(f"{w}: label: must be a non-empty string")
        if label in labels:
            raise CampaignError(f"{w}: label {label!r} is used twice; give each entry its "
                                "own label")
        labels.add(label)
        out.append(AlgorithmEntry(name, label, dict(params)))
    return out


def _command_entry(w: str, item: dict, labels: set) -> AlgorithmEntry:
    """A user program as the navigator: ``{label = "mine", command = "python nav.py"}``."""
    import shlex

    if "name" in item or "params" in item:
        raise CampaignError(f"{w}: a 'command' entry takes only 'label' and 'command'")
    cmd = item["command"]
    if isinstance(cmd, str):
        try:
            argv = shlex.split(cmd)
        except ValueError as exc:
            raise CampaignError(f"{w}: command: {exc}") from None
    elif isinstance(cmd, list) and all(isinstance(a, str) for a in cmd):
        argv = list(cmd)
    else:
        raise CampaignError(f"{w}: command: must be a command line (a string or a list of "
                            "strings)")
    if not argv:
        raise CampaignError(f"{w}: command: is empty")
    label = item.get("label")
    if not isinstance(label, str) or not label:
        raise CampaignError(f"{w}: a 'command' entry needs a 'label' (its name in the "
                            "results)")
    if label in labels:
        raise CampaignError(f"{w}: label {label!r} is used twice; give each entry its "
                            "own label")
    labels.add(label)
    return AlgorithmEntry("command", label, {"argv": argv})


def _platforms(where: str, v, files, base: Path) -> list:
    from ft_sitl.physics.catalog import PlatformRegistry
    from ft_sitl.physics.platform import PlatformError

    files = _list(f"{where}: platform_files", files) if files else []
    try:
        reg = PlatformRegistry([base / f for f in files])
    except (PlatformError, OSError, ValueError) as exc:
        raise CampaignError(f"{where}: platform_files: {exc}") from None
    everything = reg.all()
    chosen: list = []
    for k, item in enumerate(_list(f"{where}: platforms", v)):
        if not isinstance(item, str):
            raise CampaignError(f"{where}: platforms[{k}]: must be a platform name or a "
                                f"category, got {item!r}")
        if item == "all":
            picked = everything
        elif item in ("real", "virtual", "user"):
            picked = [p for p in everything if p.category == item]
            if not picked:
                raise CampaignError(f"{where}: platforms: no {item} platforms "
                                    f"(user platforms come from platform_files)")
        else:
            try:
                picked = [reg.get(item)]
            except (PlatformError, KeyError, ValueError) as exc:
                raise CampaignError(f"{where}: platforms[{k}]: {exc}") from None
        for p in picked:
            if p.name not in {q.name for q in chosen}:
                chosen.append(p)
    return chosen


def _indices(where: str, v) -> tuple[int, ...]:
    if v == "all":
        return tuple(range(1, 11))
    items = _list(where, v if not isinstance(v, int) else [v])
    return tuple(_int(where, i, 1, 10) for i in items)


def _scenarios(where: str, v, default_indices, base: Path) -> list[ScenarioEntry]:
    from ft_sitl.scenarios.families import FAMILIES, resolve_family
    from ft_sitl.scenarios.scenario import ScenarioError

    indices = _indices(f"{where}: indices", default_indices)
    if v == "all":
        return [ScenarioEntry(f, indices) for f in FAMILIES]
    out = []
    for k, item in enumerate(_list(f"{where}: scenarios", v)):
        w = f"{where}: scenarios[{k}]"
        if isinstance(item, str):
            item = {"family": item}
        if not isinstance(item, dict):
            raise CampaignError(f"{w}: must be a family name or a table")
        for key in item:
            if key not in ("family", "indices", "file"):
                raise _unknown(w, key, ("family", "indices", "file"))
        if "file" in item:
            from ft_sitl.scenarios.io import load_scenario

            if "indices" in item:
                raise CampaignError(f"{w}: indices do not apply to a scenario file (it is "
                                    "one configuration)")
            f = base / str(item["file"])
            try:
                sc = load_scenario(f)
            except ScenarioError as exc:
                raise CampaignError(f"{w}: {exc}") from None
            out.append(ScenarioEntry(sc.family, (1,), str(f.resolve())))
            continue
        try:
            fam = resolve_family(item.get("family"))
        except ScenarioError as exc:
            raise CampaignError(f"{w}: {exc}") from None
        idx = _indices(f"{w}: indices", item["indices"]) if "indices" in item else indices
        out.append(ScenarioEntry(fam, idx))
    seen: dict = {}
    for k, e in enumerate(out):
        key = e.file or e.family
        if key in seen:
            raise CampaignError(f"{where}: scenarios[{k}]: {key!r} is listed twice (also "
                                f"scenarios[{seen[key]}]); give each family once, with all "
                                "its indices")
        seen[key] = k
    return out


def _weights(where: str, v) -> dict:
    if not isinstance(v, dict):
        raise CampaignError(f"{where}: weights: must be a table")
    out = {}
    for key, val in v.items():
        if key == "beta":
            if isinstance(val, bool) or not isinstance(val, (int, float)) \
                    or not 0.0 <= val <= 1.0:
                raise CampaignError(f"{where}: weights.beta: must be within 0..1, got {val!r}")
            out["beta"] = float(val)
        elif key in ("scenarios", "platforms"):
            if not isinstance(val, dict):
                raise CampaignError(f"{where}: weights.{key}: must be a table of weights")
            for name, w in val.items():
                if isinstance(w, bool) or not isinstance(w, (int, float)) \
                        or not math.isfinite(w) or w < 0:
                    raise CampaignError(f"{where}: weights.{key}.{name}: must be a "
                                        f"non-negative number, got {w!r}")
            out[key] = {str(k): float(w) for k, w in val.items()}
        else:
            raise _unknown(f"{where}: weights", key, ("scenarios", "platforms", "beta"))
    return out


# --- executors ------------------------------------------------------------------------------
@dataclass(frozen=True)
class Transport:
    """How trials fly: ``inprocess`` (the navigator called in lockstep) or ``mavlink`` (the
    vehicle served over MAVLink at ``speed_factor``, the navigator in another process,
    ``mqtt`` the bus broker URL or None for the embedded one). A ``command`` algorithm
    always flies over MAVLink."""

    kind: str = "inprocess"
    speed_factor: float = 2.0
    mqtt: str | None = None

    def __post_init__(self):
        if self.kind not in ("inprocess", "mavlink"):
            raise CampaignError(f"--transport: {self.kind!r} is not inprocess or mavlink")
        sf = self.speed_factor
        if isinstance(sf, bool) or not isinstance(sf, (int, float)) or not 0.1 <= sf <= 20:
            raise CampaignError(f"--speed-factor: {sf!r} must be within 0.1..20")


def run_chunk(specs: list[dict], transport: Transport | None = None
              ) -> list[tuple[str, dict | None, str | None]]:
    """Run trials (as spec dicts) one after the other: (trial_id, row or None, error)."""
    out = []
    transport = transport or Transport()
    for d in specs:
        spec = TrialSpec.from_dict(d)
        try:
            if transport.kind == "mavlink" or spec.algorithm == "command":
                row = run_trial_wire(spec, speed_factor=transport.speed_factor,
                                     **worker_bus(transport.mqtt)).row
            else:
                row = run_trial(spec, wall_budget_s=wall_budget_from_env()).row
            out.append((spec.trial_id, row, None))
        except KeyboardInterrupt:
            raise
        except BaseException as exc:  # noqa: BLE001 - reported, the campaign goes on
            out.append((spec.trial_id, None, f"{type(exc).__name__}: {exc}"))
    return out


class Executor:
    """Runs chunks of trials somewhere; yields each chunk's results as it finishes."""

    def imap(self, fn: Callable[[list[dict]], list], chunks: list[list[dict]]) -> Iterator:
        raise NotImplementedError

    def close(self) -> None:
        pass


class SerialExecutor(Executor):
    """In this process, in order (``--workers 1``)."""

    def imap(self, fn, chunks):
        for chunk in chunks:
            yield chunk, fn(chunk)


def _worker_init(parent_pid: int | None = None, grid_dir: str | None = None) -> None:
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent handles Ctrl-C
    _die_with_parent(parent_pid)
    if grid_dir is not None:
        RESOURCES.share_grids(grid_dir)


def _die_with_parent(parent_pid: int | None) -> None:
    """On Linux, have the kernel send this worker SIGTERM when the campaign process dies
    (killed, say, by SIGTERM or SIGKILL, with no chance to stop its pool): orphaned workers
    would otherwise fly their queued trials to no one for minutes."""
    import sys

    if not sys.platform.startswith("linux"):
        return
    import ctypes
    import signal

    try:
        libc = ctypes.CDLL(None, use_errno=True)
        pr_set_pdeathsig = 1
        if libc.prctl(pr_set_pdeathsig, int(signal.SIGTERM), 0, 0, 0) != 0:
            return
    except (OSError, AttributeError):
        return
    if parent_pid is not None and os.getppid() != parent_pid:  # died before the prctl
        os.kill(os.getpid(), signal.SIGTERM)


class ProcessExecutor(Executor):
    """A pool of worker processes. A worker that dies (a navigator's segfault, the OOM
    killer) takes only its chunk down: that chunk is retried one trial per process, and a
    trial that kills its process again is recorded as a navigator error."""

    def __init__(self, workers: int, grid_dir: str | Path | None = None):
        self.workers = workers
        self._pool = None
        # where the workers share distance grids (removed by close(); a temporary
        # directory when not given)
        self._grid_dir_arg = grid_dir
        self._grid_dir: str | None = None

    def _new_pool(self):
        import multiprocessing as mp
        import tempfile

        if self._grid_dir is None:
            if self._grid_dir_arg is None:
                self._grid_dir = tempfile.mkdtemp(prefix="ft-sitl-grids-")
            else:
                self._grid_dir = str(self._grid_dir_arg)
                os.makedirs(self._grid_dir, exist_ok=True)

        # workers inherit the environment, with ft_sitl.numeric_env's BLAS settings (one
        # thread, pinned kernels) set on this process's import of ft_sitl
        return ProcessPoolExecutor(self.workers, mp_context=mp.get_context("spawn"),
                                   initializer=_worker_init,
                                   initargs=(os.getpid(), self._grid_dir))

    def imap(self, fn, chunks):
        pending = list(chunks)
        suspects: list[list[dict]] = []  # trials in flight when a worker died
        self._pool = self._new_pool()
        running: dict = {}
        while pending or running or suspects:
            if suspects and not running:
                # a suspect runs alone, so a death is its own
                chunk = suspects.pop(0)
                fut = self._pool.submit(fn, chunk)
                try:
                    yield chunk, fut.result()
                except BrokenProcessPool:
                    yield chunk, [_died(chunk[0])]
                    self._pool.shutdown(wait=False, cancel_futures=True)
                    self._pool = self._new_pool()
                continue
            while pending and not suspects and len(running) < 2 * self.workers:
                chunk = pending.pop(0)
                running[self._pool.submit(fn, chunk)] = chunk
            if not running:
                continue
            done, _ = wait(running, return_when=FIRST_COMPLETED)
            broken = False
            for fut in done:
                chunk = running.pop(fut)
                try:
                    yield chunk, fut.result()
                except BrokenProcessPool:
                    broken = True
                    suspects.extend([d] for d in chunk)
            if broken:
                for chunk in running.values():
                    suspects.extend([d] for d in chunk)
                running.clear()
                self._pool.shutdown(wait=False, cancel_futures=True)
                self._pool = self._new_pool()
        self.close()

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=False, cancel_futures=True)
            self._pool = None
        if self._grid_dir is not None:
            import shutil

            shutil.rmtree(self._grid_dir, ignore_errors=True)
            self._grid_dir = None


def _died(d: dict):
    """The row of a trial whose process died: a navigator error (it is the only foreign
    code a trial runs)."""
    spec = TrialSpec.from_dict(d)
    return spec.trial_id, {"__died__": True, "spec": d}, None


def _chunks(specs: list[TrialSpec]) -> list[list[dict]]:
    groups: dict = {}
    for s in specs:
        groups.setdefault((s.scenario_file, s.family, s.scenario_index), []).append(
            s.to_dict())
    out = []
    for g in groups.values():
        for k in range(0, len(g), CHUNK_MAX):
            out.append(g[k:k + CHUNK_MAX])
    return out


def died_row(d: dict) -> dict:
    """A navigator-error row for a trial whose worker process died."""
    spec = TrialSpec.from_dict(d)
    return failed_row(spec, platform_for(spec), RESOURCES.scenario(spec),
                      Outcome.NAVIGATOR_ERROR,
                      "the trial's process died (a crash in native code?)")


def machine_info() -> dict:
    """CPU model, cores, OS and Python of this machine (for reports)."""
    import platform as pyplatform

    model = pyplatform.processor() or ""
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.lower().startswith("model name"):
                    model = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    return {"cpu_model": model or "unknown", "n_cpus": os.cpu_count(),
            "os": f"{pyplatform.system()} {pyplatform.release()}",
            "python": pyplatform.python_version()}


def record_run(out_dir: Path, entry: dict) -> None:
    """Append one run's facts to DIR/runs.json (every run and resume of the campaign)."""
    import json

    path = Path(out_dir) / "runs.json"
    runs = []
    if path.exists():
        try:
            runs = json.loads(path.read_text())
        except (OSError, ValueError):
            runs = []
    runs.append(entry)
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(runs, indent=2))
    os.replace(tmp, path)


def report_meta(out_dir: Path, campaign: dict) -> dict:
    """The report's run facts from DIR/runs.json."""
    import json

    path = Path(out_dir) / "runs.json"
    runs = []
    if path.exists():
        try:
            runs = json.loads(path.read_text())
        except (OSError, ValueError):
            runs = []
    meta = {"code_version": campaign.get("code_version", __version__),
            "machine": runs[-1]["machine"] if runs else machine_info()}
    if runs:
        meta["started_utc"] = runs[0]["started_utc"]
        meta["finished_utc"] = runs[-1]["finished_utc"]
        meta["wall_time_s"] = round(sum(r["wall_time_s"] for r in runs), 2)
        meta["runs (resumes)"] = len(runs)
        meta["workers"] = runs[-1].get("workers")
    return meta


@dataclass
class RunSummary:
    total: int
    skipped: int
    ran: int
    errors: list[tuple[str, str]]
    wall_s: float


def run_campaign(campaign: Campaign, out_dir: str | Path, *, workers: int = 1,
                 executor: Executor | None = None, progress: bool = True,
                 limit: int | None = None, transport: Transport | None = None) -> RunSummary:
    """Run (or resume) a campaign into out_dir. ``limit``: stop after that many new trials
    (tests, smoke runs); ``transport``: in-process (default) or over MAVLink."""
    import functools

    from ft_sitl.missions.store import ResultStore

    try:
        wall_budget_from_env()  # a bad value is one clear error, not one per trial
    except ValueError as exc:
        raise CampaignError(str(exc)) from None
    specs = campaign.trial_specs()
    meta = {"spec": campaign.spec_dict(), "total_trials": len(specs),
            "code_version": __version__}
    store = ResultStore(out_dir)
    store.open(meta)
    todo = [s for s in specs if s.trial_id not in store.done]
    skipped = len(specs) - len(todo)
    if limit is not None:
        todo = todo[:limit]
    ex = executor or (SerialExecutor() if workers <= 1 else
                      ProcessExecutor(workers, Path(out_dir) / GRID_CACHE_DIR))
    errors: list[tuple[str, str]] = []
    t0 = time.perf_counter()
    started = time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=len(specs), initial=skipped, unit="trial", dynamic_ncols=True,
                   desc=campaign.name, smoothing=0.05)
    ran = 0
    try:
        fn = functools.partial(run_chunk, transport=transport or Transport())
        for _chunk, results in ex.imap(fn, _chunks(todo)):
            for tid, row, err in results:
                if row is not None and row.get("__died__"):
                    row = died_row(row["spec"])
                if row is not None:
                    store.append(row)
                    ran += 1
                else:
                    errors.append((tid, err))
                if bar is not None:
                    bar.update(1)
    finally:
        if bar is not None:
            bar.close()
        ex.close()
        store.close()
        wall = time.perf_counter() - t0
        record_run(Path(out_dir), {
            "started_utc": started,
            "finished_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
            "wall_time_s": round(wall, 3), "trials_run": ran, "trials_skipped": skipped,
            "errors": len(errors), "workers": workers, "machine": machine_info(),
            "transport": (transport or Transport()).kind,
            "code_version": __version__})
    if store.done:
        store.write_tables()
    return RunSummary(len(specs), skipped, ran, errors, wall)
