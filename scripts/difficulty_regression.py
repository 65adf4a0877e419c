"""Regress trial success on FlightBench's scenario-difficulty metrics and the platform's
kinodynamic indicators, and write what docs/results/scenario-difficulty/README.md shows
("Success against the metrics"):

* ``docs/results/scenario-difficulty/regression.json``: every model's coefficients
  (log-odds per standard deviation, errors clustered by platform), the pseudo-R^2 of the
  nested models and the metrics' rank correlations with the project's own measures;
* the README's tables, between their ``<!-- BEGIN generated: difficulty_regression ...
  -->`` markers.

It reads the metrics from ``docs/results/scenario-difficulty/difficulty.json`` (written by
scripts/scenario_difficulty.py) and the trials from ``docs/results/paper/trials.parquet``
(protocol 6: 36 platforms x 5 algorithms x 70 configurations); the model is
:mod:`ft_sitl.missions.difficulty_regression`. A few seconds::

    PYTHONPATH=$PWD .venv/bin/python scripts/difficulty_regression.py

``--trials`` reads another results table; ``--check`` writes nothing and exits 1 when the
README or the JSON differ from what it would write.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import ft_sitl  # noqa: F401  (first: pins the BLAS settings before numpy loads)

# isort: split
import pandas as pd

from ft_sitl.missions.difficulty_regression import (
    COMPARISON,
    design,
    fit_difficulty_models,
    markdown_coefficients,
    markdown_comparison,
    markdown_correlations,
    markdown_left_out,
    markdown_success_correlations,
    metric_correlations,
    metrics_table,
    success_correlations,
)

ROOT = Path(__file__).resolve().parents[1]
HERE = ROOT / "docs" / "results" / "scenario-difficulty"
MEASURED = HERE / "difficulty.json"
README = HERE / "README.md"
RESULTS = HERE / "regression.json"
TRIALS = ROOT / "docs" / "results" / "paper" / "trials.parquet"
END = "<!-- END generated -->"


def begin(key: str) -> str:
    return f"<!-- BEGIN generated: difficulty_regression {key} -->"


def replace_block(text: str, key: str, body: str) -> str:
    """``text`` with the block between ``key``'s markers replaced by ``body``."""
    start = text.find(begin(key))
    if start < 0:
        raise SystemExit(f"{README}: no marker {begin(key)!r}")
    end = text.index(END, start)
    return text[:start] + f"{begin(key)}\n{body}\n" + text[end:]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--trials", type=Path, default=TRIALS,
                    help="the results table (parquet) to regress (docs/results/paper's)")
    ap.add_argument("--check", action="store_true",
                    help="write nothing; exit 1 if the README or the JSON are not current")
    args = ap.parse_args(argv)
    if not args.trials.is_file():
        ap.error(f"--trials: {args.trials} is not a file")
    measured = json.loads(MEASURED.read_text())
    trials = pd.read_parquet(args.trials)
    df = design(trials, metrics_table(measured))
    result = fit_difficulty_models(df)
    fits = result["fits"]
    corr = metric_correlations(measured)
    by_success = success_correlations(df, measured)
    try:
        source = str(args.trials.resolve().relative_to(ROOT))
    except ValueError:
        source = str(args.trials)
    doc = {
        "about": "trial success against FlightBench's difficulty metrics and the "
                 "kinodynamic indicators, written by scripts/difficulty_regression.py "
                 "(docs/results/scenario-difficulty/README.md)",
        "trials": source,
        "rows": len(df),
        "protocols": sorted(int(v) for v in trials["protocol_version"].dropna().unique()),
        "fits": [f.as_dict() for f in fits],
        "comparison": result["comparison"],
        "comparison_models": {k: {"predictors": v[0], "families": v[1]}
                              for k, v in COMPARISON.items()},
        "spearman": {r: {c: round(float(corr.loc[r, c]), 4) for c in corr.columns}
                     for r in ("TO", "VO", "AOL")},
        "spearman_success": {r: {c: round(float(by_success.loc[r, c]), 4)
                                 for c in by_success.columns} for r in by_success.index},
    }
    text = README.read_text()
    new = replace_block(text, "metrics", markdown_coefficients(fits, "metrics"))
    new = replace_block(new, "families", markdown_coefficients(fits, "families"))
    new = replace_block(new, "left-out", markdown_left_out(fits, "families"))
    new = replace_block(new, "comparison", markdown_comparison(result["comparison"]))
    new = replace_block(new, "correlations", markdown_correlations(corr))
    new = replace_block(new, "success-correlations", markdown_success_correlations(by_success))
    results_text = json.dumps(doc, indent=1) + "\n"
    if args.check:
        stale = [str(p) for p, differ in (
            (README, new != text),
            (RESULTS, not RESULTS.exists() or RESULTS.read_text() != results_text),
        ) if differ]
        print("up to date" if not stale else "stale: " + ", ".join(stale))
        return 1 if stale else 0
    RESULTS.write_text(results_text)
    README.write_text(new)
    print(f"wrote {RESULTS.relative_to(ROOT)} and the tables of {README.relative_to(ROOT)} "
          f"({len(df)} trials)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
