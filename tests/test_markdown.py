"""The one Markdown table writer (ft_sitl/markdown.py)."""

import pytest

from ft_sitl import markdown as md


def test_a_table_escapes_pipes_and_line_breaks_and_aligns_its_columns():
    text = md.table(["name", "a|b"], [["x", "1\n2"], [3, 4.5]], ["", "r"])
    assert text.splitlines() == ["| name | a\\|b |", "|---|---:|", "| x | 1<br>2 |",
                                 "| 3 | 4.5 |"]


def test_alignments_must_match_the_columns():
    with pytest.raises(ValueError, match="2 alignments for 1 columns"):
        md.table(["a"], [], ["", "r"])
