"""``ft-sitl platforms`` and the controlled series: listed, shown, made for any body, and
refused with the range when a body cannot carry a request. In-process (ft_sitl.cli.main):
the console script itself is covered by test_cli.py."""

import json

import pytest

from ft_sitl.cli import main as cli_main
from ft_sitl.physics.catalog import catalog, load_platform_file, series


def cli(capsys, *args):
    code = cli_main(list(args))
    out, err = capsys.readouterr()
    return code, out, err


def test_list_shows_the_catalog_then_the_series(capsys):
    code, out, _ = cli(capsys, "platforms", "list", "--json")
    rows = json.loads(out)
    assert code == 0
    assert [r["name"] for r in rows] == list(catalog()) + list(series())
    code, out, _ = cli(capsys, "platforms", "list", "--json", "--category", "series")
    rows = {r["name"]: r for r in json.loads(out)}
    assert list(rows) == list(series())
    assert rows["series-1.00kg-SunnySky-twr1.2"]["twr_max"] == 1.2
    assert rows["series-1.00kg-SunnySky-twr1.2"]["alpha_xy_max_rad_s2"] == 227.3
    assert rows["series-5.00kg-UAV16-axy94"]["alpha_xy_max_rad_s2"] == 94.0
    code, out, _ = cli(capsys, "platforms", "list")
    lines = out.splitlines()
    assert lines[-1] == f"{len(catalog()) + len(series())} platforms"
    # the longest name keeps its columns
    long = next(line for line in lines if line.startswith("series-1.00kg-SunnySky-axy1467 "))
    assert long.split()[1:3] == ["series", "1.000"]
    assert len({line.index(" series ") for line in lines if " series " in line}) == 1


def test_show_a_series_member(capsys):
    code, out, _ = cli(capsys, "platforms", "show", "series-0.55kg-UAV1-twr6.0", "--json")
    data = json.loads(out)
    base = catalog()["0.55kg-UAV 1"]
    assert code == 0
    assert data["indicators"]["twr_max"] == 6.0
    assert data["indicators"]["alpha_xy_max_rad_s2"] == 1383.7
    assert data["physical"]["category"] == "series"
    assert data["body"] == base.body().describe()
    code, out, _ = cli(capsys, "platforms", "show", "series-0.55kg-UAV1-twr6.0")
    assert out.startswith("series-0.55kg-UAV1-twr6.0  (series, quad_x)")
    assert "source: controlled series" in out


def test_series_of_any_body_writes_a_user_file_that_loads(capsys, tmp_path):
    out_file = tmp_path / "jfrc.toml"
    code, _, err = cli(capsys, "platforms", "series", "5.45kg-JFRC", "--twr", "1.2", "2.9",
                       "--alpha-xy", "70", "300", "--out", str(out_file))
    assert code == 0 and "wrote 4 platforms" in err
    plats = load_platform_file(out_file)
    assert [p.name for p in plats] == ["series-5.45kg-JFRC-twr1.2", "series-5.45kg-JFRC-twr2.9",
                                       "series-5.45kg-JFRC-axy70", "series-5.45kg-JFRC-axy300"]
    base = catalog()["5.45kg-JFRC"]
    for p in plats:
        assert p.category == "user" and p.body() == base.body() and p.mass_kg == base.mass_kg
    assert plats[1].indicators().twr_max == pytest.approx(2.9, rel=1e-12)
    assert plats[1].indicators().alpha_xy_max_rad_s2 == pytest.approx(75.8, rel=1e-12)
    assert plats[3].indicators().alpha_xy_max_rad_s2 == pytest.approx(300.0, rel=1e-12)
    code, out, _ = cli(capsys, "platforms", "check", str(out_file))
    assert code == 0 and out.count("ok  series-5.45kg-JFRC-") == 4
    # usable beside the shipped series (other names) in every platform command
    code, out, _ = cli(capsys, "platforms", "list", "--json", "--category", "user",
                       "--platform-file", str(out_file))
    assert [r["name"] for r in json.loads(out)] == [p.name for p in plats]
    code, out, _ = cli(capsys, "platforms", "series", "5.45kg-JFRC", "--twr", "2", "--json")
    assert json.loads(out)[0]["twr_max"] == 2.0


@pytest.mark.parametrize("args, message", [
    (["5.45kg-JFRC", "--twr", "6"],
     "series of '5.45kg-JFRC': twr_max: 6 is outside the allowed range [1.05, 2.95023] for "
     "this body (holding alpha_xy 75.8 rad/s^2 above it needs more inertia"),
    (["0.55kg-UAV 1", "--twr", "1.0"],
     "twr_max: 1 is outside the allowed range [1.05, 8] for this body (hovering with a "
     "control margin needs 1.05)"),
    (["5.00kg-UAV 16", "--alpha-xy", "55.6"],
     "alpha_xy_max_rad_s2: 55.6 rad/s^2 is outside the allowed range [93.0792, 20000] "
     "rad/s^2 for this body (at TWR_max 3.5 below it needs more inertia"),
    (["0.55kg-UAV 1", "--alpha-xy", "nan"], "--alpha-xy: nan is not a finite number"),
    (["0.55kg-UAV 1"], "series: give --twr and/or --alpha-xy values"),
    (["0.55kg-UAV 1", "--twr", "2", "2.0"],
     "series: 'series-0.55kg-UAV1-twr2.0' is asked for twice"),
    (["0.55kg-UAV 9", "--twr", "2"], "unknown platform '0.55kg-UAV 9'"),
])
def test_bad_series_requests_are_one_line_errors(capsys, args, message):
    code, out, err = cli(capsys, "platforms", "series", *args)
    assert code == 2 and out == ""
    assert err.count("\n") == 1 and err.startswith("ft-sitl: error: ") and message in err


def test_a_written_file_is_not_overwritten(capsys, tmp_path):
    f = tmp_path / "s.toml"
    f.write_text("keep")
    code, _, err = cli(capsys, "platforms", "series", "0.55kg-UAV 1", "--twr", "2",
                       "--out", str(f))
    assert code == 2 and "exists (use --force to overwrite)" in err and f.read_text() == "keep"
