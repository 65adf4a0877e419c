"""What trial results depend on besides the spec: the BLAS settings (ft_sitl.numeric_env)
and numba's cache key (ft_sitl.jit_cache)."""

import json
import os
import subprocess
import sys

import pytest

from ft_sitl import numeric_env

PROBE = ("import json, ft_sitl, numpy, threadpoolctl; "
         "print(json.dumps([(i['internal_api'], i.get('architecture'), i['num_threads']) "
         "for i in threadpoolctl.threadpool_info()]))")


V3_HOST = set(numeric_env.V3_FLAGS) | {"sse2", "avx512f"}


def test_pin_sets_only_what_is_unset():
    env = {"OMP_NUM_THREADS": "4", "NPY_DISABLE_CPU_FEATURES": "AVX512_SPR"}
    done = numeric_env.pin(env, flags=V3_HOST)
    assert env["OMP_NUM_THREADS"] == "4" and "OMP_NUM_THREADS" not in done
    assert env["NPY_DISABLE_CPU_FEATURES"] == "AVX512_SPR"  # the user's
    assert {k: env[k] for k in ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_CORETYPE",
                                "NUMBA_CPU_NAME", numeric_env.EMBREE_VAR)} == {
        "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "OPENBLAS_CORETYPE": "Haswell",
        "NUMBA_CPU_NAME": "x86-64-v3", numeric_env.EMBREE_VAR: "isa=avx2"}
    assert env["NUMBA_CPU_FEATURES"] == numeric_env.V3_LLVM_FEATURES
    assert numeric_env.LEVEL_VAR not in env  # (so a set FT_SITL_ISA is the user's)
    assert "NPY_DISABLE_CPU_FEATURES" not in env[numeric_env.MARK_VAR].split(",")
    env = {"OPENBLAS_CORETYPE": "Zen"}
    numeric_env.pin(env, flags=V3_HOST)
    assert env["OPENBLAS_CORETYPE"] == "Zen"


def test_host_pins_only_the_blas():
    env = {numeric_env.LEVEL_VAR: "host"}
    numeric_env.pin(env, flags=V3_HOST)
    blas = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1",
            "OPENBLAS_CORETYPE": "Haswell"}
    assert env == {numeric_env.LEVEL_VAR: "host", **blas,
                   numeric_env.MARK_VAR: ",".join(sorted(blas))}


def test_a_child_asked_for_host_drops_the_pins_its_parent_set():
    """A process started with a pinned parent's environment (an xdist worker, a campaign
    worker) but FT_SITL_ISA=host computes at host: the parent's pins are marked as
    ft_sitl's, not the user's. A variable the user set stays."""
    parent = {"NPY_DISABLE_CPU_FEATURES": "AVX512_SPR"}
    numeric_env.pin(parent, flags=V3_HOST)
    assert parent["NUMBA_CPU_NAME"] == "x86-64-v3"
    child = {**parent, numeric_env.LEVEL_VAR: "host"}
    numeric_env.pin(child, flags=V3_HOST)
    assert "NUMBA_CPU_NAME" not in child and numeric_env.EMBREE_VAR not in child
    assert child["NPY_DISABLE_CPU_FEATURES"] == "AVX512_SPR"  # the user's
    assert numeric_env.expected_level(child, flags=V3_HOST) == "host"
    again = {**parent}
    numeric_env.pin(again, flags=V3_HOST)
    assert again == parent


def test_numpy_loaded_before_ft_sitl_is_said_not_silently_lost():
    done = numeric_env.pin({}, flags=V3_HOST)
    with pytest.warns(RuntimeWarning, match=r"numpy was imported before ft_sitl, so "
                      r"NPY_DISABLE_CPU_FEATURES, OPENBLAS_CORETYPE came too late"):
        assert numeric_env.warn_if_too_late(done, loaded={"numpy"})
    # numpy loaded after, or its variables already set by the parent: nothing to say
    assert not numeric_env.warn_if_too_late(done, loaded=set())
    assert not numeric_env.warn_if_too_late({"OMP_NUM_THREADS": "1"}, loaded={"numpy"})


@pytest.mark.e2e  # fresh interpreters
def test_a_fresh_interpreter_that_loaded_numpy_first_is_warned():
    # with none of the pins in its environment
    ours = set(numeric_env.v3_settings()) | set(numeric_env.THREAD_VARS) | {
        numeric_env.MARK_VAR}
    env = {k: v for k, v in os.environ.items() if k not in ours}
    late, first = (subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                                  text=True, timeout=120)
                   for code in ("import numpy, ft_sitl", "import ft_sitl, numpy"))
    assert late.returncode == first.returncode == 0, late.stderr + first.stderr
    assert "RuntimeWarning: numpy was imported before ft_sitl" in late.stderr
    assert "RuntimeWarning" not in first.stderr


@pytest.mark.e2e  # `python -m ft_sitl` in a child
def test_a_bad_level_is_refused_by_name(tmp_path):
    with pytest.raises(numeric_env.NumericEnvError, match=r"FT_SITL_ISA='v4' is not a level"):
        numeric_env.pin({numeric_env.LEVEL_VAR: "v4"}, flags=V3_HOST)
    env = {**os.environ, numeric_env.LEVEL_VAR: "avx512"}
    out = subprocess.run([sys.executable, "-m", "ft_sitl", "platforms", "list"], env=env,
                         capture_output=True, text=True, timeout=120)
    assert out.returncode != 0 and out.stderr.strip().splitlines() == [
        "ft-sitl: FT_SITL_ISA='avx512' is not a level ft-sitl pins: give x86-64-v3 (the "
        "default: rows equal on every processor that has it) or host (the processor's own "
        "instruction sets, as rows made before 2026-12-07)"]


def test_no_kernel_pinned_without_v3():
    import warnings

    env: dict = {}
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        numeric_env.pin(env, flags={"sse4_2", "avx"})
    assert "OPENBLAS_CORETYPE" not in env and "NUMBA_CPU_NAME" not in env
    assert "lacks" in str(caught[0].message) and "avx2" in str(caught[0].message)


def test_the_test_process_computes_at_the_pinned_level():
    """Every process of the suite computes at x86-64-v3 (conftest imports ft_sitl before
    numpy), and records it."""
    from ft_sitl.provenance import software

    if numeric_env.V3_FLAGS <= numeric_env.cpu_flags() and \
            not numeric_env.chosen_by_user():
        force = numeric_env.in_force()
        assert force["level"] == "x86-64-v3", force
        assert force["numpy_dispatch"] == "X86_V3" or "512" not in force["numpy_dispatch"]
        assert json.loads(software())["isa"] == "x86-64-v3"


@pytest.mark.e2e  # `python -c` in a child
def test_a_fresh_import_runs_one_thread_of_the_pinned_kernels():
    env = {k: v for k, v in numeric_env.child_env(numeric_env.requested()).items()
           if k not in numeric_env.THREAD_VARS + (numeric_env.CORETYPE_VAR,)}
    out = subprocess.run([sys.executable, "-c", PROBE], env=env, capture_output=True,
                         text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    pools = json.loads(out.stdout)
    blas = [p for p in pools if p[0] == "openblas"]
    assert blas, pools
    assert all(p[2] == 1 for p in blas)
    if {"avx2", "fma"} <= numeric_env.cpu_flags():
        assert all(p[1] == numeric_env.OPENBLAS_CORE for p in blas), blas


def test_jit_cache_key_covers_every_module(tmp_path):
    """numba's cache is keyed on every module of the package: an edit of a module whose
    kernels others call (navigation/optimisers/lbfgs.py, missed by a hand-kept list once) or a moved
    module gives a new cache directory."""
    import shutil
    from pathlib import Path

    import ft_sitl
    from ft_sitl.jit_cache import source_hash

    pkg = tmp_path / "ft_sitl"
    shutil.copytree(Path(ft_sitl.__file__).parent, pkg,
                    ignore=shutil.ignore_patterns("__pycache__"))
    before = source_hash(pkg)
    assert source_hash(pkg) == before
    lbfgs = pkg / "navigation" / "optimisers" / "lbfgs.py"
    lbfgs.write_text(lbfgs.read_text() + "\n# an edit\n")
    edited = source_hash(pkg)
    assert edited != before
    lbfgs.rename(pkg / "navigation" / "optimisers" / "lbfgs2.py")
    assert source_hash(pkg) != edited


def test_the_test_process_runs_the_pinned_kernels():
    """Trials flown inside pytest (run_campaign with one worker, run_trial) use the same
    BLAS kernels as the command's processes: conftest imports ft_sitl before numpy."""
    import threadpoolctl

    blas = [p for p in threadpoolctl.threadpool_info() if p["internal_api"] == "openblas"]
    assert blas and all(p["num_threads"] == 1 for p in blas)
    if {"avx2", "fma"} <= numeric_env.cpu_flags() and \
            os.environ.get(numeric_env.CORETYPE_VAR) == numeric_env.OPENBLAS_CORE:
        assert all(p["architecture"] == numeric_env.OPENBLAS_CORE for p in blas), blas


# --- the pins across processors (issue 41) ------------------------------------------------
#: a committed paper row (EGO, Forest 3) whose flight numpy's AVX-512 loops change
PAPER_ROW = "a2a810500c424167"

#: flies PAPER_ROW's spec and prints the row's digest and what computed it. With
#: "emulate", this process behaves as on another processor: LLVM reports a Haswell
#: (AVX2, FMA, no AVX-512) as the host, numpy's AVX-512 loops are off as they are on such a
#: processor, and Embree picks AVX2.
FLY = """
import sys
if sys.argv[1] == "emulate":
    import llvmlite.binding as ll

    class _Features(dict):
        def flatten(self, sort=True):
            return HASWELL

    ll.get_host_cpu_name = lambda: "haswell"
    ll.get_host_cpu_features = lambda: _Features()
import ft_sitl  # first: the pins are set before numpy loads
import hashlib, json
import pandas as pd
from ft_sitl import numeric_env
from ft_sitl.cli.missions import _NONDETERMINISTIC
from ft_sitl.missions.spec import TrialSpec
from ft_sitl.missions.trial import run_trial
df = pd.read_parquet(sys.argv[2])
spec = TrialSpec.from_dict(json.loads(df[df.trial_id == sys.argv[3]].iloc[0]["spec"]))
row = run_trial(spec).row
keep = {k: v for k, v in sorted(row.items()) if k not in _NONDETERMINISTIC}
print(json.dumps({"digest": hashlib.sha256(json.dumps(keep, default=str).encode()).hexdigest(),
                  "path": row["path_length_m"], "force": numeric_env.in_force()}))
"""
HASWELL = ("+64bit,+avx,+avx2,+bmi,+bmi2,+cmov,+crc32,+cx16,+cx8,+f16c,+fma,+fxsr,+lzcnt,"
           "+mmx,+movbe,+popcnt,+sahf,+sse,+sse2,+sse3,+sse4.1,+sse4.2,+ssse3,+xsave,"
           "+aes,+pclmul,+rdrnd,+fsgsbase,+xsaveopt,+invpcid,-avx512f,-avx512bw,-avx512dq,"
           "-avx512vl,-avx512cd")


def _fly(mode: str, level: str) -> dict:
    from pathlib import Path

    env = numeric_env.child_env(level)
    # numba's cache stays the suite's: its key holds the target (ft_sitl.jit_cache), so each
    # child loads or compiles code for its own target, and the pinned children load what
    # the suite's processes compiled instead of compiling it again (~35 s a cold compile)
    if mode == "emulate":  # what such a processor's numpy and Embree choose themselves
        env["NPY_DISABLE_CPU_FEATURES"] = numeric_env.v3_settings()["NPY_DISABLE_CPU_FEATURES"]
        env[numeric_env.EMBREE_VAR] = numeric_env.EMBREE_V3
    table = Path(__file__).resolve().parents[1] / "docs" / "results" / "paper" / \
        "trials.parquet"
    out = subprocess.run([sys.executable, "-c", f"HASWELL = {HASWELL!r}\n" + FLY, mode,
                          str(table), PAPER_ROW], env=env, capture_output=True, text=True,
                         timeout=900)
    assert out.returncode == 0, out.stderr[-3000:]
    return json.loads(out.stdout.strip().splitlines()[-1])


@pytest.mark.e2e  # four trials flown in children, two compiling for the host (~100 s)
def test_pinned_rows_are_equal_on_another_processor_and_unpinned_ones_need_not_be():
    """The same trial compiled and flown in processes that see two processors: this one,
    and one that tells numba it runs on a Haswell (a target this machine can run; numpy's
    and Embree's choices as there). Under the pins both give the same row to the last bit,
    and both say x86-64-v3 is in force; at FT_SITL_ISA=host each library takes what its
    processor offers, so on a processor with AVX-512 the two rows differ (numpy's
    AVX-512 loops, measured: docs/results/README.md)."""
    here = _fly("native", numeric_env.PINNED)
    there = _fly("emulate", numeric_env.PINNED)
    assert here["force"]["level"] == there["force"]["level"] == numeric_env.PINNED
    assert here["force"]["numba_cpu"] == there["force"]["numba_cpu"] == "x86-64-v3"
    assert here["digest"] == there["digest"], (here, there)

    host_here = _fly("native", numeric_env.HOST)
    host_there = _fly("emulate", numeric_env.HOST)
    assert host_here["force"]["level"] == host_there["force"]["level"] == numeric_env.HOST
    assert host_there["force"]["numba_cpu"] == "host"
    if "avx512f" in numeric_env.cpu_flags():
        # this processor's own loops are not the other's: the unpinned rows part
        assert host_here["digest"] != host_there["digest"], (host_here, host_there)
        # ... and the emulated processor's unpinned row is the pinned row
        assert host_there["digest"] == here["digest"]


def test_every_script_imports_ft_sitl_before_the_numeric_libraries():
    """A benchmark or script that loads numpy (or pandas, numba, ...) before ft_sitl runs
    without the pins (numpy's AVX-512 loops on such a processor): its timings and rows are
    of other arithmetic. Every module-level import of one comes after ``import ft_sitl``."""
    import ast
    from pathlib import Path

    heavy = {"numpy", "pandas", "scipy", "numba", "llvmlite", "trimesh", "matplotlib",
             "statsmodels", "torch", "benchutil"}
    root = Path(__file__).resolve().parents[1]
    bad = []
    for path in sorted([*root.glob("bench/*.py"), *root.glob("scripts/*.py"),
                        root / "tests" / "conftest.py"]):
        for node in ast.parse(path.read_text()).body:
            if isinstance(node, ast.Import):
                names = [a.name.split(".")[0] for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module:
                names = [node.module.split(".")[0]]
            else:
                continue
            if "ft_sitl" in names:
                break
            if heavy & set(names):
                bad.append(f"{path.relative_to(root)}:{node.lineno}")
                break
    assert not bad, bad


def test_the_level_a_child_will_compute_at_is_read_from_its_environment():
    v3 = numeric_env.v3_settings()
    assert numeric_env.expected_level({}, flags=V3_HOST) == "x86-64-v3"
    assert numeric_env.expected_level(dict(v3), flags=V3_HOST) == "x86-64-v3"
    assert numeric_env.expected_level({"FT_SITL_ISA": "host"}, flags=V3_HOST) == "host"
    assert numeric_env.expected_level({"NUMBA_CPU_NAME": "znver4"}, flags=V3_HOST) == "host"
    assert numeric_env.expected_level({}, flags={"sse4_2", "avx"}) == "host"


def test_a_dask_worker_refuses_chunks_of_a_campaign_at_another_level():
    from ft_sitl.missions.executors import ExecutorError, dask_chunk
    from ft_sitl.provenance import code_digest

    other = "host" if numeric_env.expected_level() == "x86-64-v3" else "x86-64-v3"
    with pytest.raises(ExecutorError, match=rf"would fly at instruction-set level "
                                            rf"{numeric_env.expected_level()}, the campaign "
                                            rf"at {other}: start every worker with "
                                            rf"FT_SITL_ISA={other}"):
        dask_chunk(lambda c: c, [], code_digest(), None, other)


def test_version_says_the_arithmetic_in_force(capsys):
    from ft_sitl import __version__
    from ft_sitl.cli import main

    with pytest.raises(SystemExit) as done:
        main(["--version"])
    assert done.value.code == 0
    out = capsys.readouterr().out.splitlines()
    force = numeric_env.in_force()
    assert out[0] == f"ft-sitl {__version__}"
    assert out[1].startswith(f"numeric libraries at {force['level']} on {force['cpu']} "
                             f"(numba {force['numba_cpu']}, numpy up to "
                             f"{force['numpy_dispatch']}")
