"""Issue 44: the capability-envelope analysis of the envelope campaigns' result
directories (docs/results/envelope/*.toml, flown into e.g. /work/runs/envelope-series):
their rows together, the tables of missions/envelope_report.py as CSV and Markdown, its
figures as PNG and SVG, and each row's time-optimal bound (the scenario's shortest path
for the platform's body, cached in ``--cache``)::

    .venv/bin/python scripts/envelope_analysis.py DIR [DIR ...] \
        --out docs/results/envelope/analysis [--protocol ego=11]

``--protocol ALGO=N`` takes that algorithm's rows only from protocol N: the envelope
campaigns fly protocol 9, and EGO's cells again under 11 (its original replanning), whose
directories are given too.
"""

# isort: off
import ft_sitl  # noqa: F401  (first: its numeric pins before numpy loads)
# isort: on

import argparse  # noqa: E402
import io  # noqa: E402
from pathlib import Path  # noqa: E402

import pandas as pd  # noqa: E402
from matplotlib import rc_context  # noqa: E402

from ft_sitl.missions import envelope  # noqa: E402
from ft_sitl.missions import envelope_report as er  # noqa: E402
from ft_sitl.missions.report import _RC  # noqa: E402
from ft_sitl.missions.results import rows_from_parquet, to_frame  # noqa: E402
from ft_sitl.missions.store import load_rows  # noqa: E402


def _rows(directory: Path) -> list[dict]:
    """A result directory's rows: its trials.jsonl (a campaign's own directory), else its
    trials.parquet (a committed one)."""
    if (directory / "trials.jsonl").exists():
        return load_rows(directory)[1]
    return rows_from_parquet(directory / "trials.parquet")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("dirs", nargs="+", type=Path, help="campaign result directories")
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--cache", type=Path, default=Path.home() / ".cache/ft-sitl/difficulty",
                    help="where the body paths are kept")
    ap.add_argument("--n-boot", type=int, default=envelope.N_BOOT)
    ap.add_argument("--families", nargs="+", metavar="FAMILY",
                    help="only these scenario families (e.g. the ones flown complete)")
    ap.add_argument("--protocol", action="append", default=[], metavar="ALGO=N",
                    help="take ALGO's rows only from protocol N (repeatable), e.g. ego=11")
    args = ap.parse_args()
    versions = {}
    for item in args.protocol:
        name, _, version = item.partition("=")
        if not name or not version.isdigit():
            ap.error(f"--protocol {item!r}: expected ALGO=N, e.g. ego=11")
        versions[name] = int(version)
    df = to_frame([r for d in args.dirs for r in _rows(d)])
    try:
        df = envelope.of_protocols(df, versions).reset_index(drop=True)
    except ValueError as exc:
        ap.error(f"--protocol: {exc}")
    if args.families:
        df = df[df["family"].astype(str).isin(args.families)].reset_index(drop=True)
    print(f"{len(df)} rows from {len(args.dirs)} directories")
    bounds = envelope.time_bounds(df, cache_dir=args.cache)
    t = er.envelope_tables(df, n_boot=args.n_boot, bounds=bounds)
    args.out.mkdir(parents=True, exist_ok=True)
    for name in ("fits", "dose", "thresholds", "tolerance", "rows"):
        getattr(t, name).to_csv(args.out / f"{name}.csv", index=False)
    (args.out / "tables.md").write_text(er.markdown(t))
    with rc_context(_RC):
        for name, caption, make in er.envelope_figures(t):
            fig = make()
            for ext in ("png", "svg"):
                buf = io.BytesIO()
                fig.savefig(buf, format=ext, dpi=120,
                            metadata={"Software": None} if ext == "png" else
                            {"Date": None, "Creator": None})
                (args.out / f"{name}.{ext}").write_bytes(buf.getvalue())
            print(f"{name}: {caption}")
    counts = df.groupby([df["algorithm"].astype(str), df[envelope.LEVEL_COLUMN].astype(str)]
                        ).size()
    print(pd.DataFrame({"rows": counts}).to_string())


if __name__ == "__main__":
    main()
