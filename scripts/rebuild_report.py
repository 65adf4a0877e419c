"""Rebuild the campaign report of a committed result directory from its rows, flying nothing.

A committed result directory (docs/results/<name>) keeps trials.parquet, runs.json and the
report's files, but not campaign.json or trials.jsonl, which `ft-sitl campaign report`
reads. This writes the report of DIR's trials.parquet into OUT/report/ with the campaign
spec shown in DIR's report.html (else {"name": DIR's name}) and the run facts of DIR's
runs.json (ft_sitl.missions.campaign.report_meta), so only the report's code and its
"generated" time can differ from the committed files. Copy OUT/report/* over DIR to
commit it.

    .venv/bin/python scripts/rebuild_report.py docs/results/paper /tmp/paper-report

Issue 44 (point 6): the paper report's figures regenerated with the readable report.
"""

from __future__ import annotations

import argparse
import html
import re
import sys
from pathlib import Path

import ft_sitl  # noqa: F401  (first: pins the numeric libraries before numpy loads)

# isort: split
import yaml

from ft_sitl.missions.campaign import report_meta
from ft_sitl.missions.report import write_report
from ft_sitl.missions.results import rows_from_parquet, to_frame


def committed_spec(directory: Path) -> dict:
    """The campaign spec a directory's report.html shows ({"name": ...} without one)."""
    page = directory / "report.html"
    if not page.exists():
        return {"name": directory.name}
    found = re.search(r"<h2>Campaign spec</h2>\s*<pre>(.*?)</pre>", page.read_text(), re.S)
    if found is None:
        sys.exit(f"{page}: no 'Campaign spec' section")
    return yaml.safe_load(html.unescape(found.group(1)))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("directory", type=Path, help="a committed result directory")
    ap.add_argument("out", type=Path, help="where to write report/")
    a = ap.parse_args()
    table = a.directory / "trials.parquet"
    if not table.exists():
        sys.exit(f"{a.directory}: no trials.parquet")
    spec = committed_spec(a.directory)
    meta = report_meta(a.directory, {"spec": spec, "code_version": ft_sitl.__version__})
    paths = write_report(to_frame(rows_from_parquet(table)), a.out, campaign_spec=spec,
                         meta=meta)
    print(paths["report.html"])


if __name__ == "__main__":
    main()
