"""The parameter schema: validation messages, defaults, display rows."""

import pytest

from ft_sitl.config import did_you_mean
from ft_sitl.schema import Param, Schema, SchemaError

S = Schema((
    Param("speed_m_s", 2.0, "m/s", (0.1, 10.0), doc="how fast"),
    Param("count", 3, "-", (1, 9), doc="how many"),
    Param("mode", "a", choices=("a", "b"), doc="which"),
    Param("flag", False, doc="whether"),
    Param("width_px", None, "px", (16, 64), kind="int", doc="optional"),
    Param("span_m", (1.0, 2.0), "m", (0.0, 5.0), kind="interval", doc="an interval"),
    Param("size_m", (4.0, 6.0), "m", (1.0, 100.0), doc="a vector"),
    Param("area_m2", None, "m^2", derived=True, doc="size_m[0] x size_m[1]"),
))


def test_resolve_fills_defaults_and_keeps_given_values():
    out = S.resolve({"count": 5, "width_px": 32}, "thing 'x'")
    assert out == {"speed_m_s": 2.0, "count": 5, "mode": "a", "flag": False, "width_px": 32,
                   "span_m": (1.0, 2.0), "size_m": (4.0, 6.0)}
    assert list(out) == S.names() and "area_m2" not in out


@pytest.mark.parametrize("values,message", [
    ({"sped_m_s": 1.0}, "thing 'x' has no parameter 'sped_m_s'; did you mean 'speed_m_s'? "
                        "(parameters: speed_m_s, count, mode, flag, width_px, span_m, size_m)"),
    ({"speed_m_s": 11.0}, "thing 'x': speed_m_s: must be a number 0.1..10 (m/s), got 11.0"),
    ({"speed_m_s": "2"}, "thing 'x': speed_m_s: must be a number 0.1..10 (m/s), got '2'"),
    ({"speed_m_s": True}, "thing 'x': speed_m_s: must be a number 0.1..10 (m/s), got True"),
    ({"speed_m_s": float("nan")}, "speed_m_s: must be a number 0.1..10 (m/s), got nan"),
    ({"count": 2.0}, "thing 'x': count: must be an integer 1..9, got 2.0"),
    ({"mode": "c"}, "thing 'x': mode: must be 'a' or 'b', got 'c'"),
    ({"flag": 1}, "thing 'x': flag: must be true or false, got 1"),
    ({"width_px": 8}, "width_px: must be an integer 16..64, or none (px), got 8"),
    ({"span_m": (2.0, 1.0)}, "span_m: must be [lo, hi] with 0 <= lo <= hi <= 5 (m)"),
    ({"span_m": (1.0, 6.0)}, "span_m: must be [lo, hi] with 0 <= lo <= hi <= 5 (m)"),
    ({"size_m": (4.0,)}, "size_m: must be 2 numbers, each 1..100 (m), got (4.0,)"),
    ({"area_m2": 3.0}, "thing 'x': area_m2 is derived from the other parameters"),
])
def test_errors_name_the_owner_key_value_and_range(values, message):
    with pytest.raises(SchemaError) as exc:
        S.validate(values, "thing 'x'")
    assert message in str(exc.value)


def test_declaration_errors():
    with pytest.raises(SchemaError, match="its default"):
        Param("x", 20.0, "m", (0.0, 10.0))
    with pytest.raises(ValueError, match="declared twice"):
        Schema((Param("x", 1.0), Param("x", 2.0)))
    with pytest.raises(ValueError, match="kind"):
        Param("x", None)
    with pytest.raises(SchemaError, match="its default"):
        S.with_defaults(count=0)
    assert S.with_defaults(count=4)["count"].default == 4 and S["count"].default == 3


def test_record_lists_every_parameter_in_order_and_needs_the_derived_ones():
    values = S.resolve({}, "t")
    rec = S.record(values, {"area_m2": 24.0})
    assert list(rec) == [p.name for p in S] and rec["area_m2"] == 24.0
    with pytest.raises(ValueError, match="missing"):
        S.record(values, {})


def test_rows_and_markdown_show_every_parameter():
    rows = S.rows()
    assert [r["name"] for r in rows] == [p.name for p in S]
    assert rows[0] == {"name": "speed_m_s", "default": "2", "unit": "m/s",
                       "range": "a number 0.1..10", "doc": "how fast"}
    assert rows[-1]["range"] == "derived" and rows[-1]["default"] == "-"
    md = S.markdown().splitlines()
    assert len(md) == 2 + len(S) and md[2].startswith("| `speed_m_s` | 2 | m/s |")


def test_did_you_mean():
    assert did_you_mean("trails", ["trials", "seed"]) == "; did you mean 'trials'?"
    assert did_you_mean("zzz", ["trials"]) == ""
