"""A campaign's result directory: durable, append-only, resumable.

Layout of ``DIR``::

    .lock              held (an exclusive flock) by the one runner using the directory
    campaign.json      the campaign as run (spec, resolved trial count, code version);
                       written once, compared on resume
    trials.jsonl       one finished trial per line (the results-table row as JSON),
                       appended, flushed and fsync'ed as each trial completes
    trials.parquet     the tidy table, rewritten from trials.jsonl at the end of a run
    report/            ``ft-sitl campaign report``

Opening takes the lock first, then checks or writes campaign.json, so two runners never
both see a directory without one. campaign.json and trials.parquet (and runs.json) are
replaced whole (:func:`~ft_sitl.missions.durable.durable_replace`): a power cut leaves the
old file or the new one, never an empty one.

A trial counts as done once its line is completely on disk. Killing the runner at any
moment (kill -9, power loss) loses at most the trials still in flight; a torn last line (a
write cut short) is cut off on the next open, before anything is appended; a damaged line
elsewhere is skipped without losing the lines after it, and reported by its line number.
Resuming skips every trial id already in the file, so no trial is lost or duplicated.

A directory that has lost its campaign.json (or holds a damaged one) but holds trials is
resumed only by the campaign those trials belong to (every stored trial id is one of the
campaign's, and every row names it); campaign.json is then written again.
"""

from __future__ import annotations

import fcntl
import json
import os
from collections.abc import Callable, Collection
from pathlib import Path

import numpy as np

from ft_sitl.autopilot.params import DEFAULT_GAINS
from ft_sitl.missions.durable import durable_replace, fsync_dir
from ft_sitl.missions.results import check_outcome, rows_from_parquet, to_frame

SPEC_FILE = "campaign.json"
TRIALS_FILE = "trials.jsonl"
PARQUET_FILE = "trials.parquet"
LOCK_FILE = ".lock"
#: damaged lines a note lists by number (the count is always given)
NOTE_LINES_MAX = 10


class StoreError(ValueError):
    """The result directory cannot be used (another campaign's results, unreadable files)."""


class ResultStore:
    def __init__(self, directory: str | Path):
        self.dir = Path(directory)
        self.trials_path = self.dir / TRIALS_FILE
        self.spec_path = self.dir / SPEC_FILE
        self._fh = None
        self._lock_fh = None
        #: the finished trials (trial id -> row): read by :meth:`open` or :meth:`load`, or
        #: on first use by :meth:`rows` (so a table is never written from an unread store)
        self.done: dict[str, dict] = {}
        self._read = False
        #: 1-based numbers of the damaged lines of trials.jsonl (skipped), as last read
        self.damaged: list[int] = []
        #: length in bytes of a torn last line of trials.jsonl (no newline), as last read
        self.torn_bytes = 0

    # --- opening ------------------------------------------------------------------------
    def open(self, campaign: dict, trial_ids: Collection[str] | None = None) -> list[str]:
        """Create the directory or reopen it for the same campaign; load finished trials.

        Takes the directory's lock first; then compares campaign.json with ``campaign``
        (writing it when the directory has none). ``trial_ids``, every trial id of the
        campaign, let a directory whose campaign.json is missing or damaged be recognised
        by its trials (without them such a directory is refused). Returns notes for the
        user: damaged lines skipped, a torn last line cut off, campaign.json written again.
        StoreError: the directory is in use, holds another campaign, or is unreadable."""
        try:
            self.dir.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise StoreError(f"--out {self.dir}: cannot create the directory: "
                             f"{exc.strerror}") from None
        self._lock()
        try:
            notes = self._check_campaign(campaign, trial_ids)
            self.done = self._load(repair=True)
            notes += self.notes(resuming=True)
            self._fh = open(self.trials_path, "ab")  # noqa: SIM115 - kept open while running
            fsync_dir(self.dir)  # trials.jsonl's entry, when it was just created
        except BaseException:
            self.close()
            raise
        return notes

    def load(self) -> dict[str, dict]:
        """Read the finished trials of the directory into :attr:`done` (trial id -> row)."""
        self.done = self._load()
        return self.done

    def notes(self, resuming: bool = False) -> list[str]:
        """What the last read of trials.jsonl skipped: damaged lines (by number) and, when
        ``resuming`` (the torn line was just cut off), a torn last line."""
        notes = []
        if self.damaged:
            n = len(self.damaged)
            numbers = ", ".join(map(str, self.damaged[:NOTE_LINES_MAX]))
            if n > NOTE_LINES_MAX:
                numbers += ", ..."
            then = ("a trial stored only there is flown again" if resuming else
                    "a trial stored only there is missing from these results until the "
                    "campaign is run again")
            notes.append(f"{self.trials_path}: {n} damaged line{'s' if n != 1 else ''} "
                         f"skipped (line{'s' if n != 1 else ''} {numbers}: not a trial "
                         f"row); {then}")
        if resuming and self.torn_bytes:
            notes.append(f"{self.trials_path}: a torn last line ({self.torn_bytes} bytes, a "
                         f"write cut short) was cut off; its trial is flown again")
        return notes

    def _check_campaign(self, campaign: dict, trial_ids: Collection[str] | None
                        ) -> list[str]:
        """Compare campaign.json with ``campaign``, or write it (under the lock)."""
        damage = None
        try:
            text = self.spec_path.read_text()
        except FileNotFoundError:
            old = None
        except (OSError, ValueError) as exc:  # (ValueError: not UTF-8)
            raise StoreError(f"{self.spec_path}: unreadable ({exc})") from None
        else:
            try:
                old = json.loads(text)
            except ValueError as exc:
                old, damage = None, "empty" if not text.strip() else f"not JSON: {exc}"
            if old is not None and not isinstance(old, dict):
                old, damage = None, "not a JSON object"
        if old is not None:
            if old.get("spec") != campaign.get("spec"):
                raise StoreError(self._mismatch(old.get("spec") or {}, campaign.get("spec")
                                                or {}))
            return []
        what = f"has no {SPEC_FILE}" if damage is None else \
            f"has a damaged {SPEC_FILE} ({damage})"
        stored = self._stored_trials(what)
        notes = []
        if stored:
            name = self._identify(stored, campaign, trial_ids, what)
            notes.append(f"{self.dir} {what}; the {len(stored)} trials it holds are all "
                         f"trials of this campaign ({name!r}): {SPEC_FILE} written again")
        elif damage is not None:
            notes.append(f"{self.spec_path} was damaged ({damage}) and no trial is stored: "
                         f"written again")
        tmp = self.spec_path.with_suffix(".tmp")
        tmp.write_text(json.dumps(campaign, indent=2, sort_keys=True))
        durable_replace(tmp, self.spec_path)
        return notes

    def _stored_trials(self, what: str) -> dict[str, object]:
        """Trial id -> campaign name of every row in trials.jsonl and trials.parquet."""
        stored = {tid: row.get("campaign") for tid, row in self._load().items()}
        parquet = self.dir / PARQUET_FILE
        if parquet.exists():
            try:
                rows = rows_from_parquet(parquet)
                for row in rows:
                    stored.setdefault(row["trial_id"], row.get("campaign"))
            except (OSError, ValueError, KeyError) as exc:
                raise StoreError(f"{self.dir} {what} and its {PARQUET_FILE} is unreadable "
                                 f"({exc}): whose trials it holds is unknown; use another "
                                 f"--out directory") from None
        return stored

    def _identify(self, stored: dict[str, object], campaign: dict,
                  trial_ids: Collection[str] | None, what: str) -> str:
        """The campaign's name if every stored trial is one of its trials, else
        StoreError saying what the directory holds."""
        name = (campaign.get("spec") or {}).get("name")
        n = len(stored)
        if trial_ids is None:
            raise StoreError(f"{self.dir} {what} and holds {n} trials, which cannot be "
                             f"checked against this campaign: use another --out directory")
        names = sorted({repr(v) for v in stored.values()})
        if names != [repr(name)]:
            raise StoreError(f"{self.dir} {what} and holds {n} trials of campaign "
                             f"{' and '.join(names)}, not of this one ({name!r}): use "
                             f"another --out directory, or the campaign file that wrote "
                             f"them to resume")
        ids = set(trial_ids)
        foreign = sum(tid not in ids for tid in stored)
        if foreign:
            raise StoreError(f"{self.dir} {what} and holds {n} trials of campaign "
                             f"{name!r}, {foreign} of which are not trials of this "
                             f"campaign file (another seed, matrix, limits, protocol or "
                             f"gains?): use another --out directory, or the campaign file "
                             f"that wrote them to resume")
        return name

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
        """The rows of trials.jsonl by trial id (the first of a repeated id); records the
        damaged lines and a torn last line, which ``repair`` cuts off."""
        done: dict[str, dict] = {}
        self.damaged = []
        self.torn_bytes = 0
        self._read = True
        if not self.trials_path.exists():
            return done
        data = self.trials_path.read_bytes()
        end = data.rfind(b"\n") + 1  # after the last complete line
        for number, line in enumerate(data[:end].split(b"\n")[:-1], start=1):
            try:
                row = json.loads(line)
                tid = row["trial_id"]
                if not isinstance(tid, str):
                    raise TypeError(tid)
            except (ValueError, KeyError, TypeError):
                self.damaged.append(number)  # skipped; the trial reruns if not elsewhere
                continue
            done.setdefault(tid, row)
        self.torn_bytes = len(data) - end
        if repair and self.torn_bytes:  # killed mid-write: cut the torn line off
            with open(self.trials_path, "r+b") as fh:
                fh.truncate(end)
                os.fsync(fh.fileno())
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

        self._lock_fh = open(self.dir / LOCK_FILE, "w")  # noqa: SIM115 - held while running
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
        """The finished trials; trials.jsonl is read first if nothing has read it yet."""
        if not self._read:
            self.load()
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


def load_rows(directory: str | Path, on_note: Callable[[str], object] | None = None
              ) -> tuple[dict, list[dict]]:
    """(campaign.json contents, finished trial rows) of a result directory; ``on_note`` is
    called with each note on what was skipped (damaged lines of trials.jsonl)."""
    d = Path(directory)
    spec_path = d / SPEC_FILE
    if not spec_path.exists():
        raise StoreError(f"{d}: not a campaign result directory (no {SPEC_FILE})")
    try:
        campaign = json.loads(spec_path.read_text())
    except (OSError, ValueError) as exc:
        raise StoreError(f"{spec_path}: unreadable ({exc})") from None
    store = ResultStore(d)
    rows = list(store.load().values())
    if on_note is not None:
        for note in store.notes():
            on_note(note)
    return campaign, rows


def _plain(v):
    if isinstance(v, np.generic):
        return v.item()
    if isinstance(v, np.ndarray):
        return v.tolist()
    raise TypeError(f"not JSON serialisable: {type(v).__name__}")
