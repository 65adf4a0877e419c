"""docs/testing.md is what runs: its example test file and its GitHub Actions workflow,
taken from the page, and its table of options against the plugin's."""

import os
import re
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
import yaml

from ft_sitl_pytest.options import OPTIONS

ROOT = Path(__file__).resolve().parents[2]
DOC = ROOT / "docs" / "testing.md"
WORKFLOW = ".github/workflows/flight-tests.yml"
#: what a package needs to be built and installed (pyproject.toml names the readme)
PACKAGE = ("pyproject.toml", "README.md", "ft_sitl", "ft_sitl_pytest")
#: the actions the workflow may use: the emulation stands in for setup-python and checkout
#: (the steps run in the directory holding the page's files); the cache and the upload of
#: a failure's files change nothing a run does
KNOWN_ACTIONS = ("actions/checkout@", "actions/setup-python@", "actions/cache@",
                 "actions/upload-artifact@")


def files_of_the_page() -> dict[str, str]:
    """The page's files: each code block after a ``<!-- file: PATH -->`` line."""
    found = re.findall(r"<!-- file: (\S+) -->\n```\w*\n(.*?)\n```", DOC.read_text(),
                       flags=re.S)
    return {path: text + "\n" for path, text in found}


def test_the_page_has_its_example_and_workflow():
    files = files_of_the_page()
    assert set(files) == {"tests/test_flight.py", WORKFLOW}
    compile(files["tests/test_flight.py"], "tests/test_flight.py", "exec")
    wf = yaml.safe_load(files[WORKFLOW])
    (job,) = wf["jobs"].values()
    runs = [s["run"] for s in job["steps"] if "run" in s]
    assert any("tests/test_flight.py" in r for r in runs)
    for step in job["steps"]:
        assert "run" in step or step["uses"].startswith(KNOWN_ACTIONS), step


def test_the_options_table_lists_every_option():
    text = DOC.read_text()
    table = text[text.index("| option | `ft-sitl sitl` | meaning |"):]
    table = table[:table.index("\n\n")]
    names = set()
    for row in table.splitlines()[2:]:
        names |= set(re.findall(r"`(\w+)`", row.split("|")[1]))
    assert names == set(OPTIONS)


def _copy_package(dest: Path) -> None:
    """This checkout's package (with what it has now, committed or not) in ``dest``."""
    dest.mkdir(parents=True)
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc", "*.nbi", "*.nbc")
    for name in PACKAGE:
        src = ROOT / name
        if src.is_dir():
            shutil.copytree(src, dest / name, ignore=ignore)
        else:
            shutil.copy2(src, dest / name)


@pytest.mark.e2e
@pytest.mark.slow
def test_the_workflow_runs_the_example_green_in_a_fresh_environment(tmp_path):
    files = files_of_the_page()
    wf = yaml.safe_load(files[WORKFLOW])
    (job,) = wf["jobs"].values()
    repo = tmp_path / "repo"  # the user's repository, as actions/checkout leaves it
    for path, text in files.items():
        (repo / path).parent.mkdir(parents=True, exist_ok=True)
        (repo / path).write_text(text)
    package = tmp_path / "ft-sitl"
    _copy_package(package)
    # actions/setup-python: a fresh interpreter of the version asked for, first on PATH
    setup = next(s for s in job["steps"] if s.get("uses", "").startswith(
        "actions/setup-python@"))
    version = setup["with"]["python-version"]
    assert version == f"{sys.version_info.major}.{sys.version_info.minor}", \
        "the emulation runs the workflow with this interpreter's version"
    base = Path(sys.base_prefix) / "bin" / f"python{version}"
    venv = tmp_path / "python"
    subprocess.run([str(base), "-m", "venv", str(venv)], check=True, timeout=300)
    env = {"PATH": f"{venv / 'bin'}:/usr/bin:/bin", "HOME": os.environ["HOME"],
           "LANG": "C.UTF-8", "CI": "true", "GITHUB_ACTIONS": "true",
           "GITHUB_WORKSPACE": str(repo), "RUNNER_TEMP": str(tmp_path)}
    env.update({k: str(v) for k, v in wf.get("env", {}).items()})
    assert "FT_SITL_PACKAGE" in env
    env["FT_SITL_PACKAGE"] = str(package)
    ran = []
    for step in job["steps"]:
        if "run" not in step or step.get("if") == "failure()":
            continue
        # as GitHub runs a bash step: bash --noprofile --norc -eo pipefail {0}
        proc = subprocess.run(["bash", "--noprofile", "--norc", "-eo", "pipefail", "-c",
                               step["run"]], cwd=repo, env=env, capture_output=True,
                              text=True, timeout=3600)
        out = proc.stdout + proc.stderr
        assert proc.returncode == 0, f"step {step.get('name')!r} failed:\n{out[-6000:]}"
        ran.append(step.get("name"))
    assert ran == ["Install ft-sitl and pytest", "Flight tests"]
    # the example's tests all ran and passed, in the fresh environment
    suite = ET.parse(repo / "flight-tests.xml").getroot().find("testsuite")
    assert (suite.get("tests"), suite.get("failures"), suite.get("errors"),
            suite.get("skipped")) == ("3", "0", "0", "0")
    # with its own pytest and ft-sitl, not this environment's
    site = subprocess.run([str(venv / "bin" / "python"), "-c",
                           "import ft_sitl, ft_sitl_pytest, pytest; print(ft_sitl.__file__, "
                           "ft_sitl_pytest.__file__, pytest.__file__)"],
                          capture_output=True, text=True, check=True, env=env,
                          cwd=tmp_path).stdout.split()
    assert all(p.startswith(str(venv)) for p in site), site
