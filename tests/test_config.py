"""ft_sitl.config: the one reader of TOML/YAML configuration files and its typed getters."""

import pytest

from ft_sitl.config import ConfigError, Table, check_keys, read_document


def _error(fn, *args, **kwargs) -> str:
    with pytest.raises(ConfigError) as exc:
        fn(*args, **kwargs)
    return str(exc.value)


def test_toml_and_yaml_give_the_same_table(tmp_path):
    (tmp_path / "a.toml").write_text('x = 1\n[t]\ny = [1.5, 2]\n')
    (tmp_path / "a.YML").write_text("x: 1\nt: {y: [1.5, 2]}\n")
    assert read_document(tmp_path / "a.toml") == read_document(tmp_path / "a.YML") == {
        "x": 1, "t": {"y": [1.5, 2]}}


def test_file_problems_name_the_file(tmp_path):
    p = tmp_path / "a.json"
    p.write_text("{}")
    assert _error(read_document, p, what="thing file") == (
        f"{p}: unknown thing file type .json; use .toml, .yaml or .yml")
    p = tmp_path / "noext"
    p.write_text("a = 1\n")
    assert _error(read_document, p) == f"{p}: unknown file type (none); use .toml, .yaml or .yml"
    for name in ("gone.toml", "gone"):  # missing: named so, whatever the suffix
        p = tmp_path / name
        assert _error(read_document, p, hint=" (presets: a, b)") == (
            f"{p}: no such file (presets: a, b)")
    p = tmp_path / "dir.yaml"
    p.mkdir()
    assert _error(read_document, p) == f"{p}: cannot read the file (Is a directory)"
    p = tmp_path / "latin.toml"
    p.write_bytes(b'x = "\xe9"\n')
    assert _error(read_document, p) == f"{p}: not a UTF-8 text file"


def test_syntax_errors_give_the_line_on_one_line(tmp_path):
    p = tmp_path / "s.toml"
    p.write_text("a = 1\nb = = 2\nc = 3\n")
    msg = _error(read_document, p)
    assert msg.startswith(f"{p}: not valid TOML: ") and "line 2" in msg
    p = tmp_path / "s.yaml"
    p.write_text("a: 1\nb: [1, 2\nc: 3\n")
    msg = _error(read_document, p)
    assert msg.startswith(f"{p}: not valid YAML (line 3, column 2): ") and "\n" not in msg


@pytest.mark.parametrize("body, got", [("- 1\n", "list"), ("", "nothing"), ("3\n", "int")])
def test_the_top_level_must_be_a_table(tmp_path, body, got):
    p = tmp_path / "t.yaml"
    p.write_text(body)
    assert _error(read_document, p, expected="a, b") == (
        f"{p}: the top level must be a table of keys (a, b), got {got}")


def test_unknown_keys_all_named_with_suggestions():
    assert _error(check_keys, "f.toml: x", {"trails": 1, "zzz": 2, "seed": 0},
                  ("trials", "seed"), context=" for a test") == (
        "f.toml: x: unknown key(s) 'trails' (did you mean 'trials'?), 'zzz' for a test; "
        "allowed: trials, seed")
    check_keys("f", {"seed": 1}, ("seed",))  # nothing unknown: no error


def test_getters_name_file_key_path_and_range():
    t = Table({"n": 11, "b": True, "f": "x", "inf": float("inf"), "v": [1, 2],
               "w": [1, "a", 3], "s": "", "sub": {"k": -1.0}, "l": []}, "f.toml")
    assert _error(t.integer, "n", lo=1, hi=10) == "f.toml: n: must be an integer 1..10, got 11"
    assert _error(t.integer, "b") == "f.toml: b: must be an integer >= 0, got True"
    assert t.integer("absent", 7) == 7
    assert _error(t.integer, "absent") == "f.toml: missing key 'absent'"
    assert _error(t.number, "f") == "f.toml: f: must be a number, got 'x'"
    assert _error(t.number, "b") == "f.toml: b: must be a number, got True"
    assert _error(t.number, "inf") == "f.toml: inf: inf is not a finite number"
    assert _error(t.number, "n", lo=0, hi=1) == "f.toml: n: must be within 0..1, got 11"
    assert t.number("n", lo=0) == 11.0 and isinstance(t.number("n"), float)
    assert _error(t.vector3, "v") == "f.toml: v: needs a list of 3 numbers [x, y, z], got [1, 2]"
    assert _error(t.vector3, "w") == "f.toml: w[1]: must be a number, got 'a'"
    assert _error(t.string, "s") == "f.toml: s: must be a non-empty string, got ''"
    assert _error(t.items, "l") == "f.toml: l: must be a non-empty list, got []"
    assert t.items("f") == ["x"]
    sub = t.table("sub")
    assert _error(sub.number, "k", lo=0) == "f.toml: sub.k: must be >= 0, got -1.0"
    assert _error(sub.check_keys, ("max",)) == (
        "f.toml: sub: unknown key(s) 'k'; allowed: max")
    assert _error(sub.require, ("k", "m", "n")) == "f.toml: missing key(s) sub.m, sub.n"
    assert _error(t.table, "n") == "f.toml: n: must be a table, got 11"
