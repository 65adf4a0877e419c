"""Where numba keeps compiled kernels, keyed by the kernels' source.

numba invalidates a cached function only when its own file changes, not when a kernel it
calls from another module does: run_steps (lockstep.py) inlines the controller
(cascade.py) and the plant (dynamics.py), and would keep stale machine code after an
edit of either (likewise fast_optim.py calling mapping.py's ESDF kernel). So every
kernel caches into one directory named after a hash of all kernel sources; any edit
starts a fresh cache. Set NUMBA_CACHE_DIR to move the root.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

_KERNEL_MODULES = (
    "__init__.py",  # G is frozen into the kernels
    "physics/quaternion.py",
    "physics/dynamics.py",
    "autopilot/cascade.py",
    "lockstep.py",
    # the planners' kernels: fast_optim calls mapping's ESDF kernel across modules
    "navigation/mapping.py",
    "navigation/astar.py",
    "navigation/ego_optim.py",
    "navigation/fast_optim.py",
    "navigation/kino_astar.py",
    "navigation/topo.py",
    "navigation/pgo.py",
)


def configure() -> Path:
    import numba

    pkg = Path(__file__).resolve().parent
    h = hashlib.sha256()
    for rel in _KERNEL_MODULES:
        h.update((pkg / rel).read_bytes())
    user_root = os.environ.get("NUMBA_CACHE_DIR")
    root = (os.path.join(user_root, "ft-sitl") if user_root else os.path.join(
        os.environ.get("XDG_CACHE_HOME") or os.path.expanduser("~/.cache"), "ft-sitl", "numba"
    ))
    path = Path(root) / h.hexdigest()[:16]
    numba.config.CACHE_DIR = str(path)
    _prune(Path(root), keep=path)
    return path


def _prune(root: Path, keep: Path, max_age_s: float = 14 * 86400) -> None:
    """Remove cache directories of other kernel versions unused for two weeks."""
    import shutil
    import time

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
