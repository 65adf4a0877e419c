"""Where numba keeps compiled kernels, keyed by the package's source.

numba invalidates a cached function only when its own file changes, not when a kernel it
calls from another module does: run_steps (sim/lockstep.py) inlines the controller
(cascade.py), the plant (dynamics.py) and the guard (sim/guard.py), and EGO's and Fast's
optimisers call navigation/optimisers/lbfgs.py; an edit of a callee would leave stale machine
code in use. So every kernel caches into one directory named after a hash of every module of the
package (a hand-kept list of kernel modules missed lbfgs.py once): any edit starts a fresh
cache. The key also holds numba's target (``ft_sitl.numeric_env``: the pinned x86-64-v3, or
the host's name and features), so code compiled under one pin is never loaded under
another. Set NUMBA_CACHE_DIR to move the root.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import time
from pathlib import Path

import numba


def source_hash(pkg: Path) -> str:
    """SHA-256 over every ``.py`` file under ``pkg``: its path relative to ``pkg`` and its
    bytes, in sorted order (a moved module changes the key too)."""
    h = hashlib.sha256()
    for path in sorted(pkg.rglob("*.py")):
        h.update(path.relative_to(pkg).as_posix().encode() + b"\0")
        h.update(path.read_bytes())
    return h.hexdigest()


def target_key() -> bytes:
    """numba's code-generation target as ft_sitl.numeric_env left it (or the host's)."""
    import llvmlite.binding as ll  # numba's own dependency, loaded with it

    cfg = numba.config
    name = cfg.CPU_NAME or ll.get_host_cpu_name()
    features = cfg.CPU_FEATURES if cfg.CPU_FEATURES is not None else \
        ll.get_host_cpu_features().flatten()
    return f"{name}\0{features}\0svml={int(not cfg.DISABLE_INTEL_SVML)}".encode()


def configure() -> Path:
    digest = hashlib.sha256(source_hash(Path(__file__).resolve().parent).encode()
                            + b"\0" + target_key()).hexdigest()
    user_root = os.environ.get("NUMBA_CACHE_DIR")
    root = (os.path.join(user_root, "ft-sitl") if user_root else os.path.join(
        os.environ.get("XDG_CACHE_HOME") or os.path.expanduser("~/.cache"), "ft-sitl", "numba"
    ))
    path = Path(root) / digest[:16]
    numba.config.CACHE_DIR = str(path)
    _prune(Path(root), keep=path)
    return path


def _prune(root: Path, keep: Path, max_age_s: float = 14 * 86400) -> None:
    """Remove cache directories of other kernel versions unused for two weeks."""

    try:
        entries = list(root.iterdir())
    except OSError:
        return
    now = time.time()
    for entry in entries:
        try:
            ours = len(entry.name) == 16 and all(ch in "0123456789abcdef" for ch in entry.name)
            if ours and entry != keep and entry.is_dir() and \
                    now - entry.stat().st_mtime > max_age_s:
                shutil.rmtree(entry, ignore_errors=True)
        except OSError:
            continue
