"""The arithmetic trial results depend on, pinned to one instruction-set level before any
numeric library loads.

A trial is a pure function of its spec only if every floating-point operation is the same
operation on every machine. The planners are chaotic enough that one last-bit difference
becomes another trajectory, and sometimes another outcome. Each numeric library picks its
machine code for the processor it finds, so without pins a row reproduces only on the
processor that made it. This module is the one place that pins them.

**The level: x86-64-v3** (``FT_SITL_ISA``, default ``x86-64-v3``). The x86-64 psABI's
level 3 is AVX, AVX2, BMI1/2, F16C, FMA, LZCNT, MOVBE and XSAVE on top of SSE4.2: every
Intel processor since Haswell (2013) and every AMD one since Zen 1 (2017) has it, so every
machine of our kind (2-core AMD EPYC cloud machines, with or without AVX-512) does. Level 4
(AVX-512) is missing on Zen 1-3 and on most Intel client processors; pinning lower (v2, no
FMA) would slow every kernel and still not reproduce the committed rows better. It is also
the level OpenBLAS's Haswell kernels are written for, which this module already pinned.

What each setting does and where it is documented:

- **BLAS threads**: ``OMP_NUM_THREADS``, ``OPENBLAS_NUM_THREADS``, ``MKL_NUM_THREADS`` = 1.
  A multi-threaded BLAS splits sums between threads (as the campaign workers always ran).
- **OpenBLAS kernels** (numpy's and scipy's, both scipy-openblas builds):
  ``OPENBLAS_CORETYPE=Haswell`` (OpenBLAS README, "Runtime CPU detection": the variable
  overrides the detected core for DYNAMIC_ARCH builds). Measured 2026-11-26: every planner
  trial of a 53-row sample differed between SkylakeX (AVX-512) and Haswell kernels.
- **numpy's dispatched SIMD loops**: ``NPY_DISABLE_CPU_FEATURES`` lists the dispatch
  targets above v3 (numpy docs, "CPU build options" / "Runtime dispatch": the variable
  disables dispatched features at import). numpy 2.4 names them ``X86_V4 AVX512_ICL
  AVX512_SPR``; earlier releases ``AVX512F AVX512CD AVX512_KNL AVX512_KNM AVX512_SKX
  AVX512_CLX AVX512_CNL AVX512_ICL AVX512_SPR``. Measured 2026-12-07 on an AVX-512 EPYC:
  numpy's AVX-512 loops alone (everything else as before) change 4 of 5 stored paper rows,
  and reproduce exactly the value an AVX2-only EPYC gave for row 65af5f4189332b4c
  (issue 41); numba's target alone changed none of them.
- **numba's target**: ``NUMBA_CPU_NAME=x86-64-v3`` and ``NUMBA_CPU_FEATURES`` = that
  level's features (numba docs, "Environment variables": both replace the host's name and
  features in code generation; the features must be given too, or the host's are used).
  ``NUMBA_DISABLE_INTEL_SVML=1``: where Intel's SVML is installed numba vectorises math
  functions with it, whose results differ from libm's.
- **Embree's ISA**: the device config string ``isa=avx2`` (Embree API, ``rtcNewDevice``:
  ``isa=`` selects the kernels instead of the best the processor has), given to the device
  :mod:`ft_sitl.scenarios.embree_packets` creates (:func:`embree_config`). Embree reads
  ``.embree4`` files in the program's and the home directory after the string: such a file
  overrides the pin. The fallback through ``embreex`` (only when Embree's library cannot be
  loaded by ctypes) creates its own device and cannot be given the string.
- **PyTorch, MKL and oneDNN** (the ``train`` extra): ``ATEN_CPU_CAPABILITY=avx2`` (PyTorch
  docs, "CPU threading and TorchScript inference" / ATen dispatch: caps ATen's kernels),
  ``MKL_CBWR=AVX2`` (MKL's conditional numerical reproducibility),
  ``MKL_ENABLE_INSTRUCTIONS=AVX2`` and ``ONEDNN_MAX_CPU_ISA=AVX2`` (oneDNN's CPU dispatcher
  control).
- **Not pinned, and why**: glibc's libm picks its ``exp``/``log``/``pow``/``sin`` variants
  by FMA and AVX2 alone (sysdeps/x86_64/fpu/multiarch), the same on every v3 machine.
  python-fcl (libfcl, libccd) and scipy's own C and Fortran code are compiled for the
  baseline with no runtime dispatch.

``FT_SITL_ISA=host`` pins none of the instruction sets (only the BLAS threads and the
Haswell BLAS kernels, as ft-sitl did before 2026-12-07): numba, numpy and Embree take what
the processor offers. Rows made before the pins were made so, on AMD EPYC processors with
AVX-512 (Zen 4, ``znver4``); they re-run bit for bit only there, with ``host``.

Variables the user set are left alone, and :func:`in_force` reports what the loaded
libraries actually use; rows, run records and the JIT cache key carry it. This runs on
``import ft_sitl``, before numba (and with it numpy) loads: a program that imported numpy
first keeps what numpy chose (:func:`in_force` then says so).
"""

from __future__ import annotations

import functools
import os
import sys
import warnings
from collections.abc import Iterable, Mapping, MutableMapping
from importlib import metadata

THREAD_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")
CORETYPE_VAR = "OPENBLAS_CORETYPE"
#: the OpenBLAS kernel set pinned on processors with AVX2 and FMA
OPENBLAS_CORE = "Haswell"

#: the variable that picks the level
LEVEL_VAR = "FT_SITL_ISA"
PINNED = "x86-64-v3"
HOST = "host"
LEVELS = (PINNED, HOST)
#: /proc/cpuinfo flags a processor needs to run x86-64-v3 code (lzcnt is "abm" there)
V3_FLAGS = frozenset({"avx", "avx2", "bmi1", "bmi2", "f16c", "fma", "abm", "movbe",
                      "xsave", "sse4_2", "popcnt"})
#: LLVM's features of x86-64-v3 (numba's NUMBA_CPU_FEATURES)
V3_LLVM_FEATURES = ("+64bit,+avx,+avx2,+bmi,+bmi2,+cmov,+crc32,+cx16,+cx8,+f16c,+fma,+fxsr,"
                    "+lzcnt,+mmx,+movbe,+popcnt,+sahf,+sse,+sse2,+sse3,+sse4.1,+sse4.2,"
                    "+ssse3,+xsave")
#: numpy's dispatch targets above x86-64-v3, by numpy release (2.4 regrouped them)
NUMPY_ABOVE_V3 = {(2, 4): "X86_V4 AVX512_ICL AVX512_SPR",
                  (0, 0): "AVX512F AVX512CD AVX512_KNL AVX512_KNM AVX512_SKX AVX512_CLX "
                          "AVX512_CNL AVX512_ICL AVX512_SPR"}
EMBREE_V3 = "isa=avx2"
#: set by :func:`pin` for :func:`embree_config` (Embree takes no environment variable)
EMBREE_VAR = "FT_SITL_EMBREE_CONFIG"


class NumericEnvError(ValueError):
    """A bad ``FT_SITL_ISA``."""


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


def _numpy_above_v3() -> str:
    try:
        major, minor = (int(p) for p in metadata.version("numpy").split(".")[:2])
    except (metadata.PackageNotFoundError, ValueError):
        major, minor = 2, 4
    for since, names in sorted(NUMPY_ABOVE_V3.items(), reverse=True):
        if (major, minor) >= since:
            return names
    return NUMPY_ABOVE_V3[(0, 0)]


def v3_settings() -> dict[str, str]:
    """The variables that make every library compute as on an x86-64-v3 processor."""
    return {CORETYPE_VAR: OPENBLAS_CORE,
            "NUMBA_CPU_NAME": PINNED, "NUMBA_CPU_FEATURES": V3_LLVM_FEATURES,
            "NUMBA_DISABLE_INTEL_SVML": "1",
            "NPY_DISABLE_CPU_FEATURES": _numpy_above_v3(),
            EMBREE_VAR: EMBREE_V3,
            "ATEN_CPU_CAPABILITY": "avx2", "MKL_CBWR": "AVX2",
            "MKL_ENABLE_INSTRUCTIONS": "AVX2", "ONEDNN_MAX_CPU_ISA": "AVX2"}


def requested(environ: MutableMapping[str, str] | None = None) -> str:
    """The level ``FT_SITL_ISA`` asks for (default x86-64-v3); a bad value is refused."""
    environ = os.environ if environ is None else environ
    level = environ.get(LEVEL_VAR, PINNED).strip() or PINNED
    if level not in LEVELS:
        raise NumericEnvError(f"{LEVEL_VAR}={level!r} is not a level ft-sitl pins: give "
                              f"{PINNED} (the default: rows equal on every processor "
                              f"that has it) or {HOST} (the processor's own instruction "
                              f"sets, as rows made before 2026-12-07)")
    return level


#: names the variables an ft_sitl process set (so a child knows they are not the user's)
MARK_VAR = "FT_SITL_PINNED_VARS"
def pin(environ: MutableMapping[str, str] | None = None,
        flags: set[str] | None = None) -> dict[str, str]:
    """Set the settings above in ``environ`` (``os.environ``) where unset; returns what
    was set. The level is ``FT_SITL_ISA``'s; on a processor without x86-64-v3 nothing but
    the threads is pinned (with a warning), and :func:`in_force` says ``host``. Variables
    a parent ft_sitl process set (:data:`MARK_VAR`) count as unset, so a child asked for
    ``host`` drops the parent's pins."""
    return _pin(os.environ if environ is None else environ, flags)


#: the variables numpy (and the OpenBLAS it loads) reads once, when it is imported
NUMPY_VARS = (CORETYPE_VAR, "NPY_DISABLE_CPU_FEATURES")


def warn_if_too_late(done: Mapping[str, str], loaded: Iterable[str] | None = None) -> bool:
    """Warn (RuntimeWarning) when :func:`pin` had to set numpy's variables (``done``)
    but numpy was already loaded (``loaded``: the modules loaded before ft_sitl), so they
    are not in force: the rows say ``isa`` host. True when it warned."""
    loaded = _IMPORTED_BEFORE if loaded is None else set(loaded)
    late = sorted(set(done) & set(NUMPY_VARS)) if "numpy" in loaded else []
    if late:
        warnings.warn(f"numpy was imported before ft_sitl, so {', '.join(late)} came too "
                      f"late: numpy computes at this host's level, rows say isa 'host' and "
                      f"need not re-fly elsewhere; import ft_sitl before numpy (or set "
                      f"FT_SITL_ISA=host to mean it)", RuntimeWarning, stacklevel=3)
    return bool(late)


def _marked(environ: MutableMapping[str, str]) -> set[str]:
    return {v for v in environ.get(MARK_VAR, "").split(",") if v}


def chosen_by_user(environ: MutableMapping[str, str] | None = None) -> bool:
    """Whether ``FT_SITL_ISA`` was set by the user (pin() never sets it)."""
    return LEVEL_VAR in (os.environ if environ is None else environ)


def child_env(level: str) -> dict[str, str]:
    """This process's environment for a child that computes at ``level``: what ft_sitl set
    (:data:`MARK_VAR`) is left out, so the child pins afresh; what the user set stays."""
    requested({LEVEL_VAR: level})
    ours = _marked(os.environ) | {MARK_VAR}
    env = {k: v for k, v in os.environ.items() if k not in ours}
    env[LEVEL_VAR] = level
    return env


def _pin(environ: MutableMapping[str, str], flags: set[str] | None) -> dict[str, str]:
    inherited = _marked(environ)
    level = requested(environ)
    flags = cpu_flags() if flags is None else flags
    pinned = level == PINNED and V3_FLAGS <= flags
    if not pinned:  # a parent's pins are not this process's
        for var in inherited & set(v3_settings()) - {CORETYPE_VAR}:
            environ.pop(var, None)
    done = {}
    for var in THREAD_VARS:
        if var not in environ:
            environ[var] = done[var] = "1"
    if level == PINNED and not pinned and flags:  # (no /proc/cpuinfo: not x86 Linux)
        warnings.warn(f"this processor lacks {', '.join(sorted(V3_FLAGS - flags))} of "
                      f"x86-64-v3: numeric libraries are not pinned, and rows made here "
                      f"need not equal rows made elsewhere", RuntimeWarning, stacklevel=3)
    if pinned:
        for var, value in v3_settings().items():
            if var not in environ:
                environ[var] = done[var] = value
    elif {"avx2", "fma"} <= flags and CORETYPE_VAR not in environ:
        environ[CORETYPE_VAR] = done[CORETYPE_VAR] = OPENBLAS_CORE
    ours = (inherited & set(environ)) | set(done)
    if ours:
        environ[MARK_VAR] = ",".join(sorted(ours))
    return done


def expected_level(environ: MutableMapping[str, str] | None = None,
                   flags: set[str] | None = None) -> str:
    """The level a process started now with ``environ`` computes at: x86-64-v3 when it asks
    for it, the processor has it and no pinned variable is set to another value; else host.
    (From the environment alone: :func:`in_force` asks the loaded libraries.)"""
    environ = os.environ if environ is None else environ
    flags = cpu_flags() if flags is None else flags
    if requested(environ) == HOST or not V3_FLAGS <= flags:
        return HOST
    same = all(environ.get(k, v) == v for k, v in v3_settings().items())
    return PINNED if same else HOST


def embree_config() -> str | None:
    """The config string for ``rtcNewDevice`` (None: Embree's own choice)."""
    return os.environ.get(EMBREE_VAR) or None


def _numpy_dispatch() -> list[str]:
    """numpy's dispatch targets active in this process, lowest first."""
    try:
        # numpy loads only after pin() has set its variables (this module loads first)
        from numpy._core import _multiarray_umath as m
    except ImportError:  # numpy 1.x
        from numpy.core import _multiarray_umath as m  # type: ignore[no-redef]
    return [t for t in m.__cpu_dispatch__ if m.__cpu_features__.get(t)]


def cpu_model_name(path: str = "/proc/cpuinfo") -> str:
    """The processor's model name ('' where /proc/cpuinfo is not readable)."""
    try:
        with open(path) as fh:
            for line in fh:
                if line.lower().startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return ""


def _cpu_model() -> str:
    model = cpu_model_name()
    try:
        # llvmlite comes with numba, which loads only after pin()
        import llvmlite.binding as ll

        host = ll.get_host_cpu_name()
    except Exception:  # noqa: BLE001 - llvmlite missing or not initialised: model alone
        host = ""
    return f"{model or 'unknown'} ({host})" if host else (model or "unknown")


@functools.cache
def in_force() -> dict:
    """What the loaded libraries compute with: ``level`` (x86-64-v3 when every pin above is
    in force, else host), ``cpu`` (the processor's model and LLVM's name for it), numba's
    target, numpy's highest active dispatch target, OpenBLAS's kernel set and Embree's
    config. Loads numba (and numpy)."""
    # numba reads its variables once, at import: only after pin() has set them
    import numba  # noqa: F401
    from numba.core import config

    numba_cpu = config.CPU_NAME or "host"
    numpy_on = _numpy_dispatch()
    facts = {"cpu": _cpu_model(), "numba_cpu": numba_cpu,
             "numpy_dispatch": numpy_on[-1] if numpy_on else "baseline",
             "openblas": os.environ.get(CORETYPE_VAR, "auto"),
             "embree": embree_config() or "auto"}
    pinned = (numba_cpu == PINNED and config.CPU_FEATURES == V3_LLVM_FEATURES
              and not any("512" in t or "V4" in t for t in numpy_on)
              and facts["openblas"] == OPENBLAS_CORE and facts["embree"] == EMBREE_V3
              and "numpy" not in _IMPORTED_BEFORE)
    return {"level": PINNED if pinned else HOST, **facts}


def record() -> dict:
    """The short form rows carry: the level and the processor."""
    f = in_force()
    return {"isa": f["level"], "cpu": f["cpu"]}


#: numeric modules already loaded when ft_sitl was imported (their choices are made)
_IMPORTED_BEFORE = frozenset(m for m in ("numpy", "numba") if m in sys.modules)
