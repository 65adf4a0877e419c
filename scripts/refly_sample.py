"""Re-fly a stratified sample of a committed result table's trials into a new directory.

Picks PER_STRATUM rows (seeded) of every (algorithm, family, platform mass tercile) stratum
of TABLE's rows and flies their stored specs again, as a resumable campaign in OUT
(trials.jsonl, trials.parquet, runs.json with the machine and the numeric pins in force,
ft_sitl.numeric_env). The re-flown rows keep their trial ids: OUT's rows compare one to
one with TABLE's (scripts/compare_refly.py).

    PYTHONPATH=$PWD .venv/bin/python scripts/refly_sample.py TABLE OUT \
        [--per-stratum 7] [--seed 0] [--workers 2] [--algorithm A ...] [--protocol N]

``--algorithm`` keeps only that algorithm's rows (repeatable). ``--protocol N`` flies the
picked specs under protocol version N instead of their own: what a protocol change does,
measured on the same trials (their ids change with the version; pair two such samples
with ``scripts/compare_refly.py A B --pair-on-spec``).

Issue 41: the paper's 12,600 rows were made before the pins; this re-flies at least 700
of them under the pins to see whether the committed rates survive another machine.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
from pathlib import Path

import ft_sitl  # noqa: F401  (first: pins the numeric libraries before numpy loads)

# isort: split
import pandas as pd

from ft_sitl.missions.campaign import run_campaign
from ft_sitl.missions.spec import TrialSpec


def pick(table: pd.DataFrame, per_stratum: int, seed: int) -> pd.DataFrame:
    """PER_STRATUM rows of every (algorithm, family, mass tercile) stratum (all of a
    smaller one), the same rows for the same seed."""
    masses = table.drop_duplicates("platform").set_index("platform")["mass_kg"]
    tercile = pd.qcut(masses.rank(method="first"), 3, labels=["small", "middle", "large"])
    table = table.assign(tercile=table["platform"].map(tercile).astype(str))
    out = []
    for _, cell in table.sort_values("trial_id").groupby(
            ["algorithm", "family", "tercile"], sort=True):
        out.append(cell.sample(min(per_stratum, len(cell)), random_state=seed))
    return pd.concat(out, ignore_index=True)


class SampleCampaign:
    """The few things run_campaign asks of a campaign, for a fixed list of specs."""

    def __init__(self, name: str, specs: list[TrialSpec], source: str, seed: int,
                 per_stratum: int, **more):
        self.name, self._specs = name, specs
        self._doc = {"name": name, "refly_of": source, "sample_seed": seed,
                     "per_stratum": per_stratum, "trials": len(specs), **more}

    def trial_specs(self) -> list[TrialSpec]:
        return list(self._specs)

    def spec_dict(self) -> dict:
        return dict(self._doc)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("table", type=Path)
    ap.add_argument("out", type=Path)
    ap.add_argument("--per-stratum", type=int, default=7)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--algorithm", action="append", default=None,
                    help="only this algorithm's rows (repeatable)")
    ap.add_argument("--protocol", type=int, default=None,
                    help="fly the picked specs under this protocol version")
    args = ap.parse_args()
    table = pd.read_parquet(args.table / "trials.parquet")
    if args.algorithm:
        unknown = sorted(set(args.algorithm) - set(table["algorithm"].astype(str)))
        if unknown:
            raise SystemExit(f"--algorithm: {', '.join(unknown)} not in {args.table}")
        table = table[table["algorithm"].isin(args.algorithm)]
    picked = pick(table, args.per_stratum, args.seed)
    specs = [TrialSpec.from_dict(json.loads(s)) for s in picked["spec"]]
    assert [s.trial_id for s in specs] == list(picked["trial_id"]), "ids do not re-hash"
    more = {}
    if args.protocol is not None:
        specs = [dataclasses.replace(s, protocol=args.protocol) for s in specs]
        more = {"protocol": args.protocol, "algorithms": args.algorithm}
    camp = SampleCampaign(f"refly-{args.table.name}", specs, str(args.table), args.seed,
                          args.per_stratum, **more)
    summary = run_campaign(camp, args.out, workers=args.workers)
    print(summary)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
