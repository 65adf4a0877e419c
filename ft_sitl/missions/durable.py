"""Durable file replacement: the one way the missions package rewrites a file in place.

A file is written whole to a temporary name beside its destination, then
:func:`durable_replace` moves it there. After a crash or a power cut the destination holds
its old contents or its new ones, never an empty or torn file: the temporary file's data
reach the disk (fsync) before the rename, and the rename itself reaches the disk (fsync of
the directory) before the function returns.
"""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["durable_replace", "fsync_dir"]


def fsync_dir(directory: str | Path) -> None:
    """Put the directory's entries (files created, renamed or removed in it) on disk."""
    fd = os.open(directory, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def durable_replace(tmp: str | Path, path: str | Path) -> None:
    """Move the finished file ``tmp`` onto ``path`` (same directory): fsync ``tmp``,
    :func:`os.replace`, fsync the directory."""
    fd = os.open(tmp, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)
    os.replace(tmp, path)
    fsync_dir(Path(path).parent)
