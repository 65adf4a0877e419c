"""A campaign's result directory: durable, append-only, resumable.

Layout of ``DIR``::

    .lock              held (an exclusive flock) by the one runner using the directory
    campaign.json      the campaign as run (spec, resolved trial count, code version);
                       written once, compared on resume
    trials.jsonl       one finished trial per line (the results-table row as JSON),
                       appended, flushed and fsync'ed as each trial completes
    trials.parquet     the tidy table, rewritten from trials.jsonl at the end of a run
    report/            ``ft-sitl campaign report``

A trial counts as done once its line is completely on disk. Killing the runner at any
moment (kill -9, power loss) loses at most the trials still in flight; a torn last line (a
write cut short) is dropped on the next open, and the file is truncated back to its last
complete line before anything is appended; a damaged line elsewhere is skipped (counted in
``damaged_lines``) without losing the lines after it. Resuming skips every trial id already
in the file, so no trial is lost or duplicated.

An exclusive lock on ``DIR/.lock`` keeps a second runner out of a directory in use; opening
takes it before campaign.json is checked or written, so two runners never both see a
directory without one. campaign.json and trials.parquet are replaced whole
(:func:`~ft_sitl.missions.durable.durable_replace`): a power cut leaves the old file or the
new one, never an empty one.
"""

from __future__ import annotations

import fcntl
import json
import os
from pathlib import Path

import numpy as np

from ft_sitl.autopilot.params import DEFAULT_GAINS
from ft_sitl.missions.durable import durable_replace, fsync_dir
from ft_sitl.missions.results import check_outcome, to_frame

SPEC_FILE = "campaign.json"
TRIALS_FILE = "trials.jsonl"
PARQUET_FILE = "trials.parquet"


class StoreError(ValueError):
    """The result directory cannot be used (another campaign's results, unreadable files)."""


class ResultStore:
    def __init__(self, directory: str | Path):
        self.dir = Path(directory)
        self.trials_path = self.dir / TRIALS_FILE
        self.spec_path = self.dir / SPEC_FILE
        self._fh = None
        self._lock_fh = None
        self.done: dict[str, dict] = {}

    # --- opening ------------------------------------------------------------------------
    def open(self, campaign: dict) -> None:
        """Create the directory or reopen it for the same campaign; load finished trials.
        Takes the directory's lock first, then compares campaign.json with ``campaign``
        (writing it when the directory has none). StoreError: the directory is in use,
        holds another campaign, or is unreadable."""
        try:
            self.dir.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise StoreError(f"--out {self.dir}: cannot create the directory: "
                             f"{exc.strerror}") from None
        self._lock()
        try:
            self._check_campaign(campaign)
            self.done = self._load(repair=True)
            self._fh = open(self.trials_path, "ab")  # noqa: SIM115 - kept open while running
            fsync_dir(self.dir)  # trials.jsonl's entry, when it was just created
        except BaseException:
            self.close()
            raise

    def _check_campaign(self, campaign: dict) -> None:
        """Compare campaign.json with ``campaign``, or write it (under the lock)."""
        if self.spec_path.exists():
            try:
                old = json.loads(self.spec_path.read_text())
            except (OSError, ValueError) as exc:
                raise StoreError(f"{self.spec_path}: unreadable ({exc})") from None
            if old.get("spec") != campaign.get("spec"):
                raise StoreError(self._mismatch(old.get("spec") or {}, campaign.get("spec")
                                                or {}))
        else:
            tmp = self.spec_path.with_suffix(".tmp")
            tmp.write_text(json.dumps(campaign, indent=2, sort_keys=True))
            durable_replace(tmp, self.spec_path)

    def load(self) -> dict[str, dict]:
        """Read the finished trials of the directory into :attr:`done` (trial id -> row)."""
        self.done = self._load()
        return self.done

    def _mismatch(self, old: dict, new: dict) -> str:
        """Why the directory's campaign is not this one; a different protocol version
        (the same campaign otherwise) is said as such."""
        v_old, v_new = old.get("protocol", 1), new.get("protocol", 1)
        if v_old != v_new and {k: v for k, v in old.items() if k != "protocol"} == \
                {k: v for k, v in new.items() if k != "protocol"}:
            return (f"{self.dir} holds trials flown under protocol version {v_old}; this "
                    f"run would fly version {v_new}, and the two do not mix in one result "
                    f"directory: set protocol = {v_old} in the campaign file to resume it, or "
                    f"use another --out directory")
        g_old, g_new = old.get("gains", DEFAULT_GAINS), new.get("gains", DEFAULT_GAINS)
        if g_old != g_new and {k: v for k, v in old.items() if k != "gains"} == \
                {k: v for k, v in new.items() if k != "gains"}:
            return (f"{self.dir} holds trials flown with gains = {g_old!r}; this run would "
                    f"fly gains = {g_new!r}: set gains = {g_old!r} in the campaign file to "
                    f"resume it, or use another --out directory")
        return (f"{self.dir} holds the results of a different campaign "
                f"({old.get('name', '?')!r}); use another --out directory, or the same "
                f"campaign file to resume")

    def _load(self, repair: bool = False) -> dict[str, dict]:
        done: dict[str, dict] = {}
        self.damaged_lines = 0
        if not self.trials_path.exists():
            return done
        data = self.trials_path.read_bytes()
        end = data.rfind(b"\n") + 1  # after the last complete line
        for line in data[:end].splitlines():
            try:
                row = json.loads(line)
                tid = row["trial_id"]
            except (ValueError, KeyError, TypeError):
                self.damaged_lines += 1  # skipped; the trial reruns if it is not elsewhere
                continue
            done.setdefault(tid, row)
        if repair and end < len(data):  # a torn tail (killed mid-write): cut it off
            with open(self.trials_path, "r+b") as fh:
                fh.truncate(end)
        return done

    # --- writing ------------------------------------------------------------------------
    def append(self, row: dict) -> None:
        """Write one finished trial durably (flush + fsync) before anything else happens.
        :class:`~ft_sitl.missions.results.RowError` (nothing written) for a row whose
        outcome is not one the protocol writes."""
        if row["trial_id"] in self.done:
            return
        check_outcome(row)
        line = json.dumps(row, sort_keys=True, allow_nan=True, default=_plain) + "\n"
        self._fh.write(line.encode())
        self._fh.flush()
        os.fsync(self._fh.fileno())
        self.done[row["trial_id"]] = row

    def _lock(self) -> None:
        """One runner per directory: an exclusive lock on DIR/.lock, held while open."""

        self._lock_fh = open(self.dir / ".lock", "w")  # noqa: SIM115 - held while running
        try:
            fcntl.flock(self._lock_fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            self._lock_fh.close()
            self._lock_fh = None
            raise StoreError(f"{self.dir} is in use by another campaign run (wait for it, or "
                             f"stop it; finished trials are kept)") from None

    def close(self) -> None:
        if self._fh is not None:
            self._fh.close()
            self._fh = None
        if self._lock_fh is not None:
            self._lock_fh.close()  # releases the lock
            self._lock_fh = None

    # --- reading ------------------------------------------------------------------------
    def rows(self) -> list[dict]:
        return list(self.done.values())

    def frame(self):
        return to_frame(self.rows())

    def write_tables(self, csv: bool = False) -> list[Path]:
        """trials.parquet (and trials.csv) from the finished trials."""
        df = self.frame()
        out = [self.dir / PARQUET_FILE]
        tmp = out[0].with_suffix(".parquet.tmp")
        df.to_parquet(tmp, index=False)
        durable_replace(tmp, out[0])
        if csv:
            out.append(self.dir / "trials.csv")
            df.to_csv(out[1], index=False)
        return out


def load_rows(directory: str | Path) -> tuple[dict, list[dict]]:
    """(campaign.json contents, finished trial rows) of a result directory."""
    d = Path(directory)
    spec_path = d / SPEC_FILE
    if not spec_path.exists():
        raise StoreError(f"{d}: not a campaign result directory (no {SPEC_FILE})")
    try:
        campaign = json.loads(spec_path.read_text())
    except (OSError, ValueError) as exc:
        raise StoreError(f"{spec_path}: unreadable ({exc})") from None
    store = ResultStore(d)
    return campaign, list(store._load().values())


def _plain(v):
    if isinstance(v, np.generic):
        return v.item()
    if isinstance(v, np.ndarray):
        return v.tolist()
    raise TypeError(f"not JSON serialisable: {type(v).__name__}")
