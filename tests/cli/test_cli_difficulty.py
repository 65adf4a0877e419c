"""``ft-sitl scenarios list | show | build --difficulty``: measured difficulty on the
command line, its cache, and the options' errors."""

import json

import pytest
import trimesh

from ft_sitl.cli import main
from ft_sitl.scenarios.families import build_scenario
from tests.scenarios.conftest import gap_spec  # noqa: F401 (the fixture)


def cli(capsys, *args):
    """(exit status, stdout, stderr) of ``ft-sitl scenarios ARGS`` run in-process."""
    rc = main(["scenarios", *args])
    out, err = capsys.readouterr()
    return rc, out, err


@pytest.fixture
def cache(tmp_path, monkeypatch):
    """A private cache directory (XDG_CACHE_HOME) for the measured difficulty."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    return tmp_path / "ft-sitl" / "difficulty"


def test_build_a_file_with_its_difficulty(capsys, cache, gap_spec):  # noqa: F811
    rc, out, err = cli(capsys, "build", "--file", str(gap_spec), "--difficulty", "--json")
    assert rc == 0, err
    d = json.loads(out)["difficulty"]
    assert d["scenario"] == "one_gap" and d["platform"] == "5.45kg-JFRC"
    assert d["path_m"] == pytest.approx(29.326, abs=0.005) and d["turns"] == 2
    assert d["passage_width_m"] == pytest.approx(1.2, abs=1e-3)
    assert d["obstacle_count"] == 2 and d["flyable"] is True
    assert d["budget"] == {"speed_m_s": 4.0, "acc_m_s2": 3.0, "time_s": 90.0}
    assert len(list(cache.glob("*.json"))) == 1
    rc, out, _ = cli(capsys, "build", "--file", str(gap_spec), "--difficulty")
    assert rc == 0
    assert "  difficulty for 5.45kg-JFRC's body (the largest), timed at 4 m/s and 3 m/s^2 " \
           "within 90 s:" in out
    assert "    shortest path 29.33 m, 1.222 x the straight line (24.00 m)" in out
    assert "    turns over 30 deg: 2 (37, 37 deg)" in out
    assert "    narrowest passage 1.200 m wide, 0.442 m to spare" in out
    assert "within the budget" in out


def test_show_measures_a_familys_configurations(capsys, cache):
    rc, out, err = cli(capsys, "show", "Sudden-Drop", "--difficulty", "--json")
    assert rc == 0, err
    doc = json.loads(out)
    assert doc["family"] == "sudden_drop" and doc["parameters"]
    rows = doc["difficulty"]["configurations"]
    assert [r["index"] for r in rows] == list(range(1, 11))
    assert [r["obstacle_count"] for r in rows] == list(range(1, 11))  # blocks = index
    assert all(r["passage_width_m"] == pytest.approx(1.5, abs=1e-6) for r in rows)
    assert doc["difficulty"]["summary"]["flyable"] == 10
    assert len(list(cache.glob("*.json"))) == 10
    # the text again, from the cache: the same numbers
    rc, out, _ = cli(capsys, "show", "sudden_drop", "--difficulty")
    assert rc == 0
    lines = out.splitlines()
    table = lines[lines.index(next(ln for ln in lines if ln.startswith("config "))) + 1:]
    assert [ln.split()[0] for ln in table] == [f"sudden_drop-{i:02d}-s0" for i in range(1, 11)]
    assert all(ln.endswith("  yes") and " 1.500 " in ln for ln in table)
    assert len(list(cache.glob("*.json"))) == 10


def test_seed_and_no_cache(capsys, cache):
    rc, out, err = cli(capsys, "show", "sudden_drop", "--difficulty", "--seed", "3",
                       "--no-cache", "--json")
    assert rc == 0, err
    rows = json.loads(out)["difficulty"]["configurations"]
    assert [r["scenario"] for r in rows] == [f"sudden_drop-{i:02d}-s3" for i in range(1, 11)]
    layout = build_scenario("sudden_drop", 4, 3).provenance["layout"]["blocks_y_m"]
    assert rows[3]["obstacle_count"] == len(layout) == 4
    assert not cache.exists()  # --no-cache writes nothing


@pytest.mark.parametrize("args,message", [
    (("list", "--seed", "2"), "--seed only applies with --difficulty"),
    (("list", "--no-cache"), "--no-cache only applies with --difficulty"),
    (("show", "maze", "--seed", "1", "--no-cache"),
     "--seed and --no-cache only apply with --difficulty"),
    (("show", "maze", "--difficulty", "--seed", "-1"),
     "--seed: -1 must be a non-negative integer"),
    (("list", "--difficulty", "--seed", "-4"), "--seed: -4 must be a non-negative integer"),
    (("build", "maze", "--no-cache"), "--no-cache only applies with --difficulty"),
    (("show", "mazes", "--difficulty"), "unknown scenario family 'mazes'; did you mean"),
    (("build", "maze", "--index", "11", "--difficulty"), "--index: 11 must be within 1..10"),
])
def test_bad_options_are_one_line_errors(capsys, cache, args, message):
    rc, out, err = cli(capsys, *args)
    assert (rc, out) == (2, "")
    assert err.startswith("ft-sitl: error: ") and message in err
    assert len(err.strip().splitlines()) == 1
    assert not cache.exists()


def test_bad_option_values_are_refused_by_the_parser(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["scenarios", "list", "--difficulty", "--seed", "x"])
    assert exc.value.code == 2
    assert "--seed: invalid int value: 'x'" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["scenarios", "export", "maze", "--difficulty"])  # not an option of export
    assert "unrecognized arguments: --difficulty" in capsys.readouterr().err


def test_a_scenario_without_a_path(capsys, cache, tmp_path):
    """A wall across the whole area: no path for the body, said so, not in the budget."""
    trimesh.creation.box(bounds=[[0.0, 9.0, 0.0], [20.0, 10.0, 6.0]]).export(
        tmp_path / "wall.ply")
    spec = tmp_path / "blocked.toml"
    spec.write_text('name = "blocked"\nmesh = "wall.ply"\nstart = [10.0, 3.0, 2.0]\n'
                    'goal = [10.0, 17.0, 2.0]\nbounds_min = [0.0, 0.0, 0.0]\n'
                    'bounds_max = [20.0, 20.0, 4.0]\n')
    rc, out, err = cli(capsys, "build", "--file", str(spec), "--difficulty", "--json")
    assert rc == 0, err
    d = json.loads(out)["difficulty"]
    assert d["path_m"] is None and d["turns"] is None and d["time_s"] is None
    assert d["flyable"] is False and d["obstacle_count"] == 1
    assert d["occupied_fraction"] == pytest.approx(20 * 1 * 4 / (20 * 20 * 4))
    rc, out, _ = cli(capsys, "build", "--file", str(spec), "--difficulty")
    assert rc == 0 and "    no path found for the body" in out


def test_an_unwritable_cache_is_a_clear_error(capsys, tmp_path, monkeypatch):
    blocker = tmp_path / "not-a-dir"
    blocker.write_text("")
    monkeypatch.setenv("XDG_CACHE_HOME", str(blocker))  # the cache would go under a file
    rc, out, err = cli(capsys, "build", "sudden_drop", "--difficulty")
    assert (rc, out) == (2, "")
    assert "cannot write the difficulty cache in" in err and "--no-cache" in err
    rc, out, err = cli(capsys, "build", "sudden_drop", "--difficulty", "--no-cache")
    assert rc == 0 and "flight time at best" in out
