"""Noise for the compiled kernels: a counter-based standard normal generator.

A draw is a pure function of (seed, physics step, component), so a vehicle's noise does
not depend on how its steps are batched, on the other vehicles, or on anything else that
draws random numbers (the wind's turbulence and the actuators' command noise use it).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_GOLD = np.uint64(0x9E3779B97F4A7C15)


@njit(cache=True, inline="always")
def _mix(z):
    z = (z ^ (z >> np.uint64(30))) * _M1
    z = (z ^ (z >> np.uint64(27))) * _M2
    return z ^ (z >> np.uint64(31))


@njit(cache=True, inline="always")
def _uniforms(seed, k, j):
    z = (np.uint64(seed) * _GOLD + np.uint64(k + 1) * np.uint64(8) + np.uint64(j))
    a = _mix(z)
    b = _mix(a ^ _GOLD)
    u1 = (float(a >> np.uint64(11)) + 0.5) * (1.0 / 9007199254740992.0)
    u2 = float(b >> np.uint64(11)) * (1.0 / 9007199254740992.0)
    return u1, u2


@njit(cache=True)
def gauss_pair(seed, k, j):
    """Two independent standard normal numbers, a pure function of (seed, step k,
    component j): both halves of one Box-Muller draw (half the cost of two gauss calls)."""
    u1, u2 = _uniforms(seed, k, j)
    r = math.sqrt(-2.0 * math.log(u1))
    return r * math.cos(2.0 * math.pi * u2), r * math.sin(2.0 * math.pi * u2)


@njit(cache=True)
def gauss(seed, k, j):
    """A standard normal number, a pure function of (seed, step k, component j).

    Hand-written (SplitMix64 finalizer + Box-Muller) because it runs inside the compiled
    physics step, where numpy's Generator objects are not available and numba's global
    np.random state would make a trial's wind depend on what else drew from it."""
    u1, u2 = _uniforms(seed, k, j)
    return math.sqrt(-2.0 * math.log(u1)) * math.cos(2.0 * math.pi * u2)


