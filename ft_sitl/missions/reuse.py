"""Rows another result directory already holds, taken into a campaign instead of flown again.

Two campaigns that differ in a setting that changes only some trials (the thrust floor,
which leaves every trial of a platform whose floor stays PX4's untouched; a new
aggressiveness level beside old ones) share the other trials: the same canonical spec, so
the same trial id (:meth:`~ft_sitl.missions.spec.TrialSpec.trial_id`), and a trial re-flies
bit for bit from its spec. ``ft-sitl campaign run --reuse DIR`` copies such rows into the
new directory before anything flies, so only the trials that differ are flown.

A row is taken only when its trial id is one of the campaign's, the new directory does not
hold it yet, and its own spec still hashes to its id under this code (a row written under
another canonical form is flown again rather than trusted). Each copied row is appended
durably as a flown one is; what was taken from where goes into runs.json.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Collection, Sequence
from pathlib import Path

from ft_sitl.missions.spec import TrialSpec, TrialSpecError
from ft_sitl.missions.store import SPEC_FILE, ResultStore, StoreError, load_rows


def spec_matches(row: dict) -> bool:
    """The row's spec hashes to its trial id under this code's canonical form."""
    spec = row.get("spec")
    try:
        d = json.loads(spec) if isinstance(spec, str) else spec
        return TrialSpec.from_dict(d).trial_id == row.get("trial_id")
    except (TypeError, ValueError, KeyError, TrialSpecError):
        return False


def check_sources(sources: Sequence[str | Path], out_dir: str | Path) -> None:
    """StoreError naming the first of ``sources`` that is not another result directory
    (checked before the campaign's own directory is created)."""
    for src in sources:
        src = Path(src)
        if src.resolve() == Path(out_dir).resolve():
            raise StoreError(f"--reuse {src}: is the campaign's own --out directory")
        if not (src / SPEC_FILE).is_file():
            raise StoreError(f"--reuse {src}: not a campaign result directory (no "
                             f"{SPEC_FILE})")


def reuse_rows(store: ResultStore, sources: Sequence[str | Path], wanted: Collection[str],
               append: Callable[[dict], None] | None = None) -> dict[str, int]:
    """Append to ``store`` (open) every row of ``sources`` whose trial id is in ``wanted``
    and not yet in the store, and whose spec matches its id; ``append`` writes one row (the
    campaign passes one that defers signals). Returns rows taken per source directory.
    StoreError: a source that is not a result directory, or is the store itself."""
    append = append or store.append
    wanted = set(wanted)
    taken: dict[str, int] = {}
    check_sources(sources, store.dir)
    for src in sources:
        src = Path(src)
        try:
            _, rows = load_rows(src)
        except StoreError as exc:
            raise StoreError(f"--reuse {src}: {exc}") from None
        n = 0
        for row in rows:
            tid = row.get("trial_id")
            if tid in wanted and tid not in store.done and spec_matches(row):
                append(row)
                n += 1
        taken[str(src)] = n
    return taken
