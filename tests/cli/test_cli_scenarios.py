"""``ft-sitl scenarios``: list, build, export and render, with real files.

Most tests call ``ft_sitl.cli.main`` in-process (the same code path as the console script,
without paying the interpreter start-up each time); a few run the installed script.
"""

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from ft_sitl.cli import main
from ft_sitl.scenarios.families import FAMILIES, PAPER_NAMES, build_scenario

EXE = shutil.which("ft-sitl", path=str(Path(sys.executable).parent))
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def run_exe(*args):
    assert EXE, "the ft-sitl console script is not installed next to this Python"
    return subprocess.run([EXE, *args], capture_output=True, text=True, timeout=120)


def cli(capsys, *args):
    """(exit status, stdout, stderr) of ``ft-sitl scenarios ARGS`` run in-process."""
    rc = main(["scenarios", *args])
    out, err = capsys.readouterr()
    return rc, out, err


@pytest.mark.e2e
def test_help_and_list_json_from_the_installed_script():
    assert "scenarios" in run_exe("--help").stdout
    helptext = run_exe("scenarios", "--help").stdout
    for action in ("list", "build", "export", "render"):
        assert action in helptext
    proc = run_exe("scenarios", "list", "--json")
    assert proc.returncode == 0, proc.stderr
    rows = json.loads(proc.stdout)
    assert [r["family"] for r in rows] == list(FAMILIES)
    assert [r["paper_name"] for r in rows] == [PAPER_NAMES[f] for f in FAMILIES]
    by = {r["family"]: r for r in rows}
    assert by["forest"]["area_m"] == [40.0, 60.0] and by["forest"]["ceiling_m"] == 3.0
    assert by["urban"]["category"] == "classic" and by["maze"]["category"] == "theoretical"
    assert by["sudden_drop"]["area_m"] == [50.0, 50.0] and by["sudden_drop"]["ceiling_m"] == 4.0
    assert all(r["description"] for r in rows)


def test_show_prints_a_familys_generator_parameters(capsys):
    from ft_sitl.scenarios.families import describe_family

    rc, out, _ = cli(capsys, "show", "Narrow-Gap")
    assert rc == 0
    lines = out.splitlines()
    assert lines[0].startswith("narrow_gap (Narrow-Gap, theoretical): ")
    declared = describe_family("narrow_gap").schema.rows()
    assert len(lines) == 2 + len(declared)
    assert any(ln.startswith("gap_width_m ") and "[0.85, 0.9]" in ln for ln in lines)
    rc, out, _ = cli(capsys, "show", "forest", "--json")
    doc = json.loads(out)
    assert doc["family"] == "forest" and doc["parameters"] == describe_family(
        "forest").schema.rows()
    rc, out, err = cli(capsys, "show", "forst")
    assert (rc, out) == (2, "")
    assert "unknown scenario family 'forst'; did you mean 'forest'?" in err


@pytest.mark.slow
def test_list_text(capsys):
    rc, out, _ = cli(capsys, "list")
    assert rc == 0
    lines = out.splitlines()
    assert lines[0].split()[:3] == ["family", "paper", "name"]
    assert len(lines) == 1 + len(FAMILIES) + 1
    assert "Random Perlin-Noise" in out and "25 x 40" in out


def test_build_text_and_json_match_the_library(capsys):
    rc, out, _ = cli(capsys, "build", "Narrow-Gap", "--index", "4", "--seed", "3", "--json")
    assert rc == 0
    ref = build_scenario("narrow_gap", 4, 3)
    assert json.loads(out) == ref.summary()
    rc, out, _ = cli(capsys, "build", "narrow gap", "--index", "4", "--seed", "3")
    assert rc == 0
    assert out.splitlines()[0] == "narrow_gap-04-s3  (Narrow-Gap, theoretical)"
    assert f"obstacles 4: {len(ref.mesh.vertices)} vertices, {len(ref.mesh.faces)} triangles" \
        in out
    assert f"mesh sha256 {ref.mesh_digest()}" in out
    assert "start   (25.00, 3.00, 2.00), yaw 90.0 deg" in out and "built in" in out


def test_render_default_name_and_trajectory(capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    rc, out, err = cli(capsys, "render", "maze", "--index", "2", "--dpi", "60")
    assert rc == 0, err
    png = tmp_path / "maze-02-s0.png"
    assert out.strip() == "wrote maze-02-s0.png" and png.read_bytes()[:8] == PNG_MAGIC
    sc = build_scenario("urban", 1, 0)
    traj = tmp_path / "flown.csv"
    rows = np.linspace(sc.start, sc.goal, 20)
    traj.write_text("t,x,y,z\n" + "".join(f"{k},{x},{y},{z}\n" for k, (x, y, z) in
                                          enumerate(rows)))
    out_png = tmp_path / "pics" / "urban.png"
    out_png.parent.mkdir()
    rc, _, err = cli(capsys, "render", "urban", "--trajectory", str(traj), "-o", str(out_png))
    assert rc == 0, err
    assert out_png.read_bytes()[:8] == PNG_MAGIC and out_png.stat().st_size > 30_000


@pytest.mark.parametrize("args, needle", [
    (["build", "forst"], "unknown scenario family 'forst'; did you mean 'forest'?"),
    (["build", "forest", "--index", "11"], "--index: 11 must be within 1..10"),
    (["render", "maze", "--index", "0"], "--index: 0 must be within 1..10"),
    (["build", "forest", "--seed", "-1"], "--seed: -1 must be a non-negative integer"),
    (["build"], "give a scenario FAMILY"),
    (["build", "forest", "--file", "spec.yaml"], "give a FAMILY or --file, not both"),
    (["build", "--file", "missing.yaml"], "--file: missing.yaml does not exist"),
    (["render", "forest", "-o", "pic.jpg"], "--out: pic.jpg must end in .png"),
    (["render", "forest", "-o", "nodir/pic.png"], "--out: directory nodir does not exist"),
    (["render", "forest", "--trajectory", "nope.csv"], "--trajectory: nope.csv: no such file"),
    (["render", "forest", "--trajectory", "bad.csv"],
     "--trajectory: bad.csv: line 2, column 'y': 'oops' is not a number"),
    (["render", "forest", "--dpi", "5"], "--dpi: 5 must be within 10..1200"),
    (["export", "forest", "--format", "stl"], "--format: 'stl' is not one of"),
    (["export", "forest"], "--format: give one of"),
])
def test_bad_input_is_one_line_exit_2(capsys, tmp_path, monkeypatch, args, needle):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "bad.csv").write_text("x,y,z\n1,oops,3\n")
    rc, out, err = cli(capsys, *args)
    assert rc == 2, (out, err)
    assert err.startswith("ft-sitl: error: ") and err.count("\n") == 1, err
    assert needle in err, err
    assert not list(tmp_path.glob("*.png"))


@pytest.mark.e2e
def test_bad_family_from_the_installed_script():
    proc = run_exe("scenarios", "render", "Narow-Gap")
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1
    assert "'narrow_gap'" in proc.stderr and "Traceback" not in proc.stderr


def test_export_every_format(capsys, tmp_path, monkeypatch):
    from ft_sitl.scenarios.io import EXPORT_FORMATS

    monkeypatch.chdir(tmp_path)
    for fmt in EXPORT_FORMATS:
        rc, out, err = cli(capsys, "export", "sudden_drop", "--index", "2", "--format", fmt)
        assert rc == 0, (fmt, err)
        main_file = tmp_path / f"sudden_drop-02-s0.{fmt}"
        assert f"wrote {main_file.name}" in out.splitlines()
        for line in out.splitlines():
            assert Path(line.removeprefix("wrote ")).stat().st_size > 0, line
    rc, out, err = cli(capsys, "export", "forest", "-o", "sub.ply", "--json")  # from suffix
    assert rc == 0, err
    assert json.loads(out)["format"] == "ply" and (tmp_path / "sub.ply").stat().st_size > 0


def test_export_spec_round_trips_through_file(capsys, tmp_path):
    out_dir = tmp_path / "w"
    out_dir.mkdir()
    rc, out, err = cli(capsys, "export", "Random-Angle Cylinder", "--index", "3", "--seed",
                       "2", "--format", "obj", "-o", str(out_dir / "rac.obj"), "--spec",
                       "--json")
    assert rc == 0, err
    files = [Path(f) for f in json.loads(out)["files"]]
    spec = out_dir / "rac.yaml"
    assert spec in files and all(f.exists() for f in files)
    rc, out, err = cli(capsys, "build", "--file", str(spec), "--json")
    assert rc == 0, err
    ref = build_scenario("random_angle_cylinder", 3, 2).summary()
    got = json.loads(out)
    assert (got["family"], got["category"]) == ("random_angle_cylinder-03-s2", "user")
    for key in ("bounds_min", "bounds_max", "takeoff", "start", "goal", "goal_radius_m"):
        assert got[key] == ref[key], key
    assert got["start_yaw_rad"] == pytest.approx(ref["start_yaw_rad"], abs=1e-12)
    assert got["mesh"]["sha256"] == ref["mesh"]["sha256"]  # the spec's PLY is exact
    rc, _, err = cli(capsys, "render", "--file", str(spec), "-o", str(out_dir / "rac.png"))
    assert rc == 0, err
    assert (out_dir / "rac.png").read_bytes()[:8] == PNG_MAGIC
    rc, _, err = cli(capsys, "build", "--file", str(spec), "--seed", "1")
    assert rc == 2 and "--index and --seed do not apply to --file" in err
