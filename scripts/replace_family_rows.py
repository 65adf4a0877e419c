"""Replace one scenario family's rows of a committed result table with a re-flown run.

When a family's generator gets a new version, the other families' rows stay valid: only
that family is flown again (a campaign naming ``{ family = ..., version = N }``) and its
rows are swapped into the table. This writes TABLE/trials.parquet with every row of
TABLE except FAMILY's, plus every row of RUN (which must hold FAMILY's rows only, for the
same algorithms, platforms, configurations and trials, under the same protocol), and
appends RUN's runs.json records to TABLE's. The old rows stay in git history.

    PYTHONPATH=$PWD .venv/bin/python scripts/replace_family_rows.py TABLE RUN FAMILY

TABLE and RUN are result directories (trials.parquet, or a campaign's trials.jsonl).
"""

from __future__ import annotations

import argparse
import json
import sys
from collections import Counter
from pathlib import Path

import ft_sitl  # noqa: F401  (first: pins the BLAS settings before numpy loads)

# isort: split
import pandas as pd

#: what a cell is: the trial numbers and seeds may differ (a campaign of one family numbers
#: its trials from 0, where the family was part of a bigger campaign)
CELL = ["algorithm", "platform", "scenario_index", "scenario_seed"]


def read_rows(directory: Path) -> pd.DataFrame:
    if (directory / "trials.parquet").exists():
        return pd.read_parquet(directory / "trials.parquet")
    jsonl = directory / "trials.jsonl"
    if not jsonl.exists():
        raise SystemExit(f"{directory}: no trials.parquet or trials.jsonl")
    return pd.read_json(jsonl, lines=True, dtype=False)


def replace(table: pd.DataFrame, run: pd.DataFrame, family: str) -> pd.DataFrame:
    """TABLE's rows without FAMILY's, then RUN's; SystemExit naming what does not match."""
    if set(run["family"]) != {family}:
        raise SystemExit(f"the run holds families {sorted(set(run['family']))}, not only "
                         f"{family!r}")
    old = table[table["family"] == family]
    if old.empty:
        raise SystemExit(f"the table has no {family!r} rows to replace")
    if run["trial_id"].duplicated().any():
        raise SystemExit("the run has duplicate trial ids")
    if set(run["protocol_version"]) != set(table["protocol_version"]):
        raise SystemExit(f"protocol_version: the run has {sorted(set(run['protocol_version']))}"
                         f", the table {sorted(set(table['protocol_version']))}")

    def cells(df):
        return Counter(map(tuple, df[CELL].astype(str).to_numpy()))

    if cells(run) != cells(old):
        missing, extra = cells(old) - cells(run), cells(run) - cells(old)
        raise SystemExit(f"the run's cells differ from the table's {family!r} cells: "
                         f"{sum(missing.values())} missing (e.g. {sorted(missing)[:2]}), "
                         f"{sum(extra.values())} extra (e.g. {sorted(extra)[:2]})")
    if set(run["trial_id"]) & set(table["trial_id"]):
        raise SystemExit("the run repeats trial ids of the table: it is not a new version")
    missing_cols = [c for c in table.columns if c not in run.columns]
    if missing_cols:
        raise SystemExit(f"the run's rows lack the table's columns {missing_cols}")
    return pd.concat([table[table["family"] != family], run[list(table.columns)]],
                     ignore_index=True)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("table", type=Path, help="the committed result directory")
    ap.add_argument("run", type=Path, help="the re-flown family's result directory")
    ap.add_argument("family", help="the family whose rows are replaced")
    args = ap.parse_args(argv)
    table, run = read_rows(args.table), read_rows(args.run)
    out = replace(table, run, args.family)
    out.to_parquet(args.table / "trials.parquet", index=False)
    runs_path = args.table / "runs.json"
    runs = json.loads(runs_path.read_text()) if runs_path.exists() else []
    new_runs = json.loads((args.run / "runs.json").read_text()) \
        if (args.run / "runs.json").exists() else []
    for r in new_runs:
        r.setdefault("note", f"re-flew {args.family} only ({len(run)} rows)")
    runs_path.write_text(json.dumps(runs + new_runs, indent=1) + "\n")
    print(f"{args.table}/trials.parquet: {len(table)} rows -> {len(out)} "
          f"({len(table) - len(out) + len(run)} {args.family} rows replaced by {len(run)})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
