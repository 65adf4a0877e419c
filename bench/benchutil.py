"""Helpers shared by the benchmark scripts: one pinned CPU, repeated timing, machine facts."""

from __future__ import annotations

# isort: off
import ft_sitl  # noqa: F401  (first: its numeric pins before numpy loads)
# isort: on

import datetime
import gc
import os
import platform as pyplatform
import statistics
import subprocess
import time

import numpy as np


def pin_to_one_cpu(cpu: int | None) -> int | None:
    """Pin this process to one CPU (the last allowed one by default). Returns it, or None."""
    if not hasattr(os, "sched_setaffinity"):
        return None
    allowed = sorted(os.sched_getaffinity(0))
    target = allowed[-1] if cpu is None else cpu
    os.sched_setaffinity(0, {target})
    return target


def timed(fn, repeats: int) -> dict:
    """Run fn() `repeats` times; wall seconds per run and CPU share, GC off while timing."""
    walls, shares = [], []
    gc.collect()
    gc.disable()
    try:
        for _ in range(repeats):
            c0, t0 = time.process_time(), time.perf_counter()
            fn()
            t1, c1 = time.perf_counter(), time.process_time()
            walls.append(t1 - t0)
            shares.append((c1 - c0) / (t1 - t0))
    finally:
        gc.enable()
    return {"wall_s": walls, "median_s": statistics.median(walls), "min_s": min(walls),
            "max_s": max(walls), "cpu_share_median": statistics.median(shares),
            "cpu_share_max": max(shares)}


def machine_info(cpu: int | None, **extra) -> dict:
    """Date, CPU model, CPU count, pinned CPU, memory, load, Python/numpy, plus extra."""
    model = pyplatform.processor() or ""
    try:
        lscpu = subprocess.run(["lscpu"], capture_output=True, text=True, timeout=10).stdout
        for line in lscpu.splitlines():
            if line.lower().startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except (OSError, subprocess.SubprocessError):
        pass
    mem_gb = None
    try:
        mem_gb = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 2**30
    except (ValueError, OSError, AttributeError):
        pass
    return {
        "date_utc": datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%dT%H:%M:%SZ"),
        "cpu_model": model,
        "n_cpus": os.cpu_count(),
        "pinned_cpu": cpu,
        "mem_gib": mem_gb,
        "load_avg_1min": os.getloadavg()[0] if hasattr(os, "getloadavg") else None,
        "python": pyplatform.python_version(),
        "numpy": np.__version__,
        "machine": pyplatform.machine(),
        **extra,
    }
