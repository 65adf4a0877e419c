"""Benchmark: Gymnasium environment steps per second on one core (issue 25).

``ftsitl/Navigate-v0`` in Forest configuration 5 (seed 0): velocity actions at 50 Hz
(20 physics steps at 1 kHz of the full flight-controller cascade each), catalog platforms
drawn per episode, episodes ending as the benchmark's referee ends them (collisions,
bounds, the goal) and autoreset. The actions are a random walk in the action space biased
forward, so vehicles fly into the trees and episodes end and restart during the timing.

Measured per case, ``--repeats`` times (median, min..max):

* **single**: :class:`~ft_sitl.gym.envs.NavigateEnv` as ``gymnasium.make`` builds it
  (with Gymnasium's order-enforcing and passive-checker wrappers), reset by the loop;
* **vector N** for N = 1, 16, 256: :class:`~ft_sitl.gym.envs.NavigateVectorEnv`, N
  vehicles in one compiled physics call, next-step autoreset;

each with the ray scan (the default), without a sensor, and with the 32 x 24 depth image.
The figure is environment steps per wall second summed over the vehicles (one step: one
vehicle's action, 20 ms of its flight); multiplied by 0.02 it is simulated seconds per
wall second.

    NUMBA_NUM_THREADS=1 .venv/bin/python bench/bench_gym.py          # ~4 min
    NUMBA_NUM_THREADS=1 .venv/bin/python bench/bench_gym.py --json
"""

from __future__ import annotations

# isort: off
import ft_sitl  # noqa: F401  (its BLAS settings before numpy loads)
# isort: on

import argparse  # noqa: E402
import json  # noqa: E402
import os  # noqa: E402
import statistics  # noqa: E402
import subprocess  # noqa: E402
import time  # noqa: E402

import gymnasium as gym  # noqa: E402
import numpy as np  # noqa: E402
from benchutil import machine_info, pin_to_one_cpu  # noqa: E402

import ft_sitl.gym  # noqa: E402, F401  (registers the environments)
from ft_sitl.gym import NavigateVectorEnv  # noqa: E402

SETTINGS = {"scenario_index": (5, 5)}
SENSORS = ("rays", "none", "depth")
SIZES = (1, 16, 256)


def actions(rng: np.random.Generator, prev: np.ndarray) -> np.ndarray:
    """A random walk in [-1, 1] biased forward (goal-frame x)."""
    a = np.clip(0.9 * prev + 0.3 * rng.uniform(-1.0, 1.0, prev.shape), -1.0, 1.0)
    a[..., 0] = np.clip(a[..., 0] + 0.05, -1.0, 1.0)
    return a


def single(sensor: str, steps: int, repeats: int) -> dict:
    env = gym.make("ftsitl/Navigate-v0", sensor=sensor, **SETTINGS)
    rng = np.random.default_rng(0)
    env.reset(seed=0)
    a = np.zeros(4)

    def run():
        nonlocal a
        ends = 0
        for _ in range(steps):
            a = actions(rng, a)
            _, _, term, trunc, _ = env.step(a.astype(np.float32))
            if term or trunc:
                env.reset()
                ends += 1
        return ends

    run()  # (compiles and builds the world: not timed)
    return timed(run, steps, repeats)


def vector(n: int, sensor: str, steps: int, repeats: int) -> dict:
    env = NavigateVectorEnv(n, sensor=sensor, **SETTINGS)
    rng = np.random.default_rng(0)
    env.reset(seed=0)
    a = np.zeros((n, 4))

    def run():
        nonlocal a
        ends = 0
        for _ in range(steps):
            a = actions(rng, a)
            _, _, term, trunc, _ = env.step(a.astype(np.float32))
            ends += int(np.count_nonzero(term | trunc))
        return ends

    run()
    return timed(run, steps * n, repeats)


def timed(run, env_steps: int, repeats: int) -> dict:
    rates, shares, ends = [], [], 0
    for _ in range(repeats):
        c0, t0 = time.process_time(), time.perf_counter()
        ends += run()
        t1, c1 = time.perf_counter(), time.process_time()
        rates.append(env_steps / (t1 - t0))
        shares.append((c1 - c0) / (t1 - t0))
    return {"env_steps_per_s": statistics.median(rates), "min": min(rates),
            "max": max(rates), "cpu_share_median": statistics.median(shares),
            "episodes_ended_per_repeat": ends / repeats, "env_steps_per_repeat": env_steps}


def commit() -> str:
    try:
        here = os.path.dirname(os.path.abspath(__file__))
        return subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True,
                              text=True, cwd=here, timeout=10).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return ""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--steps", type=int, default=400,
                    help="environment steps per repeat of each vehicle (400: 8 s of "
                    "flight, several episodes each)")
    ap.add_argument("--cpu", type=int, default=None, help="the CPU to pin to (default: the "
                    "last allowed)")
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args()
    os.environ.setdefault("NUMBA_NUM_THREADS", "1")
    cpu = pin_to_one_cpu(a.cpu)
    out = {"machine": machine_info(cpu, commit=commit(),
                                   numba_threads=os.environ["NUMBA_NUM_THREADS"],
                                   gymnasium=gym.__version__),
           "settings": {**{k: list(v) for k, v in SETTINGS.items()},
                        "control_hz": 50, "physics_hz": 1000, "action": "velocity"},
           "results": []}
    for sensor in SENSORS:
        r = single(sensor, a.steps, a.repeats)
        out["results"].append({"env": "single (gymnasium.make)", "vehicles": 1,
                               "sensor": sensor, **r})
        for n in SIZES:
            r = vector(n, sensor, a.steps, a.repeats)
            out["results"].append({"env": "vector", "vehicles": n, "sensor": sensor, **r})
    if a.json:
        print(json.dumps(out, indent=1))
        return
    m = out["machine"]
    print(f"{m['date_utc']}  {m['cpu_model']}  pinned to CPU {m['pinned_cpu']}  "
          f"commit {m['commit']}  load {m['load_avg_1min']:.2f}")
    print(f"{'env':<26}{'N':>5}{'sensor':>8}{'env steps/s':>14}{'min..max':>20}"
          f"{'x real time':>13}{'cpu share':>11}")
    for r in out["results"]:
        print(f"{r['env']:<26}{r['vehicles']:>5}{r['sensor']:>8}"
              f"{r['env_steps_per_s']:>14,.0f}{r['min']:>10,.0f}..{r['max']:<9,.0f}"
              f"{r['env_steps_per_s'] * 0.02:>13,.0f}{r['cpu_share_median']:>11.2f}")


if __name__ == "__main__":
    main()
