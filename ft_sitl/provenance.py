"""What made a result: the ft_sitl code (a digest of its files) and the versions of the
libraries a trial's numbers go through. Recorded in every trial row (``software``) and
compared between a campaign and its Dask workers."""

from __future__ import annotations

import functools
import hashlib
import json
import sys
from importlib import metadata
from pathlib import Path

from ft_sitl import __version__, numeric_env

#: distributions whose versions can change a trial's floating-point results
NUMERIC_PACKAGES = ("numpy", "numba", "llvmlite", "scipy", "trimesh", "python-fcl",
                    "embreex", "torch")


@functools.cache
def code_digest() -> str:
    """SHA-256 over the source and data files of the installed ft_sitl package: two
    processes with the same digest fly the same trials to the same rows (the version
    string alone does not change between commits)."""
    root = Path(__file__).resolve().parent
    h = hashlib.sha256()
    for path in sorted(root.rglob("*")):
        if path.suffix not in (".py", ".toml", ".csv", ".json", ".yaml") or \
                "__pycache__" in path.parts or not path.is_file():
            continue
        h.update(path.relative_to(root).as_posix().encode())
        h.update(b"\0")
        h.update(path.read_bytes())
        h.update(b"\0")
    return h.hexdigest()


@functools.cache
def software() -> str:
    """The ``software`` column: JSON of ft_sitl's version and code digest (16 hex), Python's
    version, the installed versions of :data:`NUMERIC_PACKAGES` (absent ones left out), the
    instruction-set level the numeric libraries computed at (``isa``: x86-64-v3 or host,
    :mod:`ft_sitl.numeric_env`) and the processor (``cpu``)."""
    out = {"ft_sitl": __version__, "code": code_digest()[:16],
           "python": ".".join(map(str, sys.version_info[:3])), **numeric_env.record()}
    for name in NUMERIC_PACKAGES:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            pass
    return json.dumps(out, sort_keys=True, separators=(",", ":"))
