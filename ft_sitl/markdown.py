"""Markdown tables: the one writer the reports, the docs' generated tables and the
scripts share."""

from __future__ import annotations

from collections.abc import Iterable, Sequence


def cell(value) -> str:
    """A value as a table cell: a literal ``|`` escaped, a line break as ``<br>``."""
    return str(value).replace("|", "\\|").replace("\n", "<br>")


def table(head: Sequence, rows: Iterable[Sequence], align: str | Sequence[str] = "") -> str:
    """A Markdown table of ``head`` and ``rows`` (cells by :func:`cell`). ``align`` gives
    each column's rule: "" (left, ``---``), "r" (``---:``) or "c" (``:---:``), one string
    per column or one for all."""
    n = len(head)
    aligns = [align] * n if isinstance(align, str) else list(align)
    if len(aligns) != n:
        raise ValueError(f"table: {len(aligns)} alignments for {n} columns")
    rule = {"": "---", "r": "---:", "c": ":---:"}
    lines = ["| " + " | ".join(cell(h) for h in head) + " |",
             "|" + "".join(rule[a] + "|" for a in aligns)]
    lines += ["| " + " | ".join(cell(c) for c in r) + " |" for r in rows]
    return "\n".join(lines)
