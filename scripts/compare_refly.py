"""Compare a re-flown sample (scripts/refly_sample.py) with the committed rows it re-flew.

Joins OUT's rows with TABLE's by trial id and prints, as Markdown:

- how many rows are identical (every column but the wall-clock ones and ``software``),
  how many end the same way, and the outcome changes (stored -> re-flown);
- success per algorithm, per family and per (algorithm, family): stored and re-flown,
  each with its Wilson 95 % interval, and McNemar's exact test on the paired outcomes
  (the same trials flown twice: only the trials whose outcome changed carry information);
- whether the order of the algorithms by success, overall and in each family, is the same.

    PYTHONPATH=$PWD .venv/bin/python scripts/compare_refly.py TABLE OUT > OUT/comparison.md

``--pair-on-spec`` pairs rows whose specs are the same but for the protocol version (two
samples of refly_sample.py ``--protocol``, whose trial ids differ); ``--labels A B`` names
the two sides in the tables (default: stored, re-flown under the pins).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import ft_sitl  # noqa: F401  (first: the numeric pins before numpy loads)

# isort: split
import pandas as pd
from statsmodels.stats.contingency_tables import mcnemar

from ft_sitl import markdown as md
from ft_sitl.cli.missions import differences
from ft_sitl.missions.scoring import wilson_interval


def read(directory: Path) -> pd.DataFrame:
    if (directory / "trials.parquet").exists():
        return pd.read_parquet(directory / "trials.parquet")
    # (json, not pandas' reader: its default float parsing is not exact to the last bit)
    lines = (directory / "trials.jsonl").read_text().splitlines()
    return pd.DataFrame([json.loads(line) for line in lines if line.strip()])


def rate(s: pd.Series) -> str:
    n, k = len(s), int(s.sum())
    lo, hi = wilson_interval(n, k)
    return f"{k}/{n} = {k / n:.2f} [{lo:.2f}, {hi:.2f}]"


def paired(a: pd.Series, b: pd.Series) -> str:
    """McNemar's exact p for paired outcomes a (stored) and b (re-flown)."""
    up = int((~a & b).sum())
    down = int((a & ~b).sum())
    if up + down == 0:
        return "1.00 (no change)"
    p = mcnemar([[0, down], [up, 0]], exact=True).pvalue
    return f"{p:.2f} ({down} lost, {up} gained)"


LABELS = ["stored", "re-flown under the pins"]


def spec_key(spec: str) -> str:
    """A trial's spec without its protocol version: the pairing key of --pair-on-spec."""
    d = json.loads(spec)
    d.pop("protocol", None)
    return json.dumps(d, sort_keys=True)


def table(both: pd.DataFrame, by: list[str]) -> list[str]:
    rows = []
    for key, g in both.groupby(by, sort=True):
        key = key if isinstance(key, tuple) else (key,)
        rows.append([*key, rate(g.success_s), rate(g.success_n),
                     paired(g.success_s, g.success_n)])
    return md.table([*by, *LABELS, "McNemar p"], rows,
                    [""] * len(by) + ["r"] * 3).split("\n")


def order(both: pd.DataFrame, col: str, family: str | None = None) -> list[str]:
    g = both if family is None else both[both.family == family]
    s = g.groupby("algorithm")[col].mean().sort_values(ascending=False, kind="stable")
    return list(s.index)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("table", type=Path)
    ap.add_argument("out", type=Path)
    ap.add_argument("--pair-on-spec", action="store_true",
                    help="pair rows by their spec without the protocol version")
    ap.add_argument("--labels", nargs=2, metavar=("A", "B"), default=None)
    args = ap.parse_args()
    if args.labels:
        LABELS[:] = args.labels
    key = (lambda df: df["spec"].map(spec_key)) if args.pair_on_spec else \
        (lambda df: df["trial_id"])
    stored, new = read(args.table), read(args.out)
    stored = stored.set_index(key(stored), drop=False)
    new = new.set_index(key(new), drop=False)
    missing = [t for t in new.index if t not in stored.index]
    if missing:
        raise SystemExit(f"{len(missing)} re-flown rows are not in {args.table}")
    rows = []
    for k, r in new.iterrows():
        s = stored.loc[k]
        tid = r["trial_id"]
        d = differences({**r.to_dict(), "trial_id": tid}, {**s.to_dict(), "trial_id": tid})
        if args.pair_on_spec:  # (the version and what names it differ by construction)
            d = [c for c in d if c.split(" ")[0] not in ("spec", "protocol_version")]
        rows.append({"trial_id": tid, "algorithm": r.algorithm, "family": r.family,
                     "success_s": bool(s.success), "success_n": bool(r.success),
                     "reason_s": s.reason, "reason_n": r.reason, "identical": not d})
    both = pd.DataFrame(rows)
    n = len(both)
    same_end = int((both.reason_s == both.reason_n).sum())
    a_side, b_side = LABELS
    lines = [f"{n} rows paired: {int(both.identical.sum())} identical ({b_side} against "
             f"{a_side}), {same_end} ending the same way ({same_end / n:.1%}), "
             f"{int((both.success_s != both.success_n).sum())} changing success.", ""]
    flips = both[both.reason_s != both.reason_n].groupby(
        ["algorithm", "reason_s", "reason_n"]).size()
    if len(flips):
        lines += [f"| algorithm | {a_side} | {b_side} | rows |", "|---|---|---|---:|"]
        lines += [f"| {a} | {rs} | {rn} | {k} |" for (a, rs, rn), k in flips.items()]
        lines.append("")
    for by in (["algorithm"], ["family"], ["algorithm", "family"]):
        lines += table(both, by) + [""]
    agree = []
    for fam in [None, *sorted(both.family.unique())]:
        a, b = order(both, "success_s", fam), order(both, "success_n", fam)
        agree.append(f"- {fam or 'all families'}: {a_side} {' > '.join(a)}; {b_side} "
                     f"{' > '.join(b)}{'' if a == b else '  (ORDER CHANGED)'}")
    lines += [f"Order of the algorithms by success (ties in the order of {a_side}):",
              *agree]
    print("\n".join(lines))
    summary = {"rows": n, "identical": int(both.identical.sum()), "same_end": same_end}
    print(json.dumps(summary), file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
