"""The numeric libraries' settings that trial results depend on, pinned before numpy loads.

A trial is a pure function of its spec only if every floating-point sum is computed in the
same order. Two settings of the BLAS library numpy loads change that order:

- threads: a multi-threaded BLAS splits sums between threads. One thread, as the campaign
  workers always ran.
- the kernel set: OpenBLAS picks its kernels for the processor it finds. On a processor
  with AVX-512 it takes its SkylakeX kernels, whose dot products differ in the last bits
  from the AVX2 (Haswell/Zen) kernels the committed results were made with; the planners'
  trajectories then drift apart. Measured on 2026-11-26: every planner trial of a
  53-row sample of the protocol-1 paper run (then docs/results/paper) differed on an
  AVX-512 host, and all were identical with ``OPENBLAS_CORETYPE=Haswell``. So on a
  processor that has AVX2 and FMA the Haswell kernels are used.

Variables the user set are left alone. This runs on ``import ft_sitl``, before numba (and
with it numpy) loads; a program that imported numpy first keeps what its BLAS chose.
"""

from __future__ import annotations

import os
from collections.abc import MutableMapping

THREAD_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")
CORETYPE_VAR = "OPENBLAS_CORETYPE"
#: the OpenBLAS kernel set pinned on processors with AVX2 and FMA
OPENBLAS_CORE = "Haswell"


def cpu_flags(path: str = "/proc/cpuinfo") -> set[str]:
    """The processor's feature flags (empty where /proc/cpuinfo is not readable)."""
    try:
        with open(path) as fh:
            for line in fh:
                if line.startswith("flags"):
                    return set(line.split(":", 1)[1].split())
    except OSError:
        pass
    return set()


def pin(environ: MutableMapping[str, str] | None = None,
        flags: set[str] | None = None) -> dict[str, str]:
    """Set the defaults above in ``environ`` (``os.environ``) where unset; returns what was
    set."""
    environ = os.environ if environ is None else environ
    done = {}
    for var in THREAD_VARS:
        if var not in environ:
            environ[var] = done[var] = "1"
    if CORETYPE_VAR not in environ:
        flags = cpu_flags() if flags is None else flags
        if {"avx2", "fma"} <= flags:
            environ[CORETYPE_VAR] = done[CORETYPE_VAR] = OPENBLAS_CORE
    return done
