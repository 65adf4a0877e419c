"""What trial results depend on besides the spec: the BLAS settings (ft_sitl.numeric_env)
and numba's cache key (ft_sitl.jit_cache)."""

import json
import os
import subprocess
import sys

from ft_sitl import numeric_env

PROBE = ("import json, ft_sitl, numpy, threadpoolctl; "
         "print(json.dumps([(i['internal_api'], i.get('architecture'), i['num_threads']) "
         "for i in threadpoolctl.threadpool_info()]))")


def test_pin_sets_only_what_is_unset():
    env = {"OMP_NUM_THREADS": "4"}
    done = numeric_env.pin(env, flags={"avx2", "fma", "sse4_2"})
    assert env == {"OMP_NUM_THREADS": "4", "OPENBLAS_NUM_THREADS": "1",
                   "MKL_NUM_THREADS": "1", "OPENBLAS_CORETYPE": "Haswell"}
    assert "OMP_NUM_THREADS" not in done
    env = {"OPENBLAS_CORETYPE": "Zen"}
    numeric_env.pin(env, flags={"avx2", "fma"})
    assert env["OPENBLAS_CORETYPE"] == "Zen"


def test_no_kernel_pinned_without_avx2():
    env: dict = {}
    numeric_env.pin(env, flags={"sse4_2"})
    assert "OPENBLAS_CORETYPE" not in env


def test_a_fresh_import_runs_one_thread_of_the_pinned_kernels():
    env = {k: v for k, v in os.environ.items()
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
    kernels others call (navigation/lbfgs.py, missed by a hand-kept list once) or a moved
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
    lbfgs = pkg / "navigation" / "lbfgs.py"
    lbfgs.write_text(lbfgs.read_text() + "\n# an edit\n")
    edited = source_hash(pkg)
    assert edited != before
    lbfgs.rename(pkg / "navigation" / "lbfgs2.py")
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
