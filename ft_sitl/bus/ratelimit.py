"""RateGate: when the next sample of a stream is due, in simulated time.

The publisher never rate-limits by itself (it sends what it is given); the caller decides
what to publish. ``RateGate(20.0).take(t_us)`` is True once per 1/20 s of simulated time:

    gate = RateGate(20.0)
    ...
    if gate.take(sim.time_us):
        publisher.publish_telemetry(sample)

The schedule is a grid anchored at the first sample: sample k is due at
``t0 + ceil(k * 1e6 / rate_hz)`` us, so the rate does not drift when the caller's step does
not divide the period (20 Hz stepped at 3 ms still gives 20 samples per simulated second).
A caller that falls behind gets one sample, not a burst: the next slot after ``t_us``.
"""

from __future__ import annotations

import math
import numbers

__all__ = ["RateGate"]

#: Largest rate a gate accepts (Hz).
MAX_RATE_HZ = 1e6


class RateGate:
    """Say when the next sample is due at ``rate_hz`` of simulated time (0 = never)."""

    def __init__(self, rate_hz: float):
        self._rate = self._check(rate_hz)
        self._t0_us: int | None = None
        self._next_us: int | None = None

    @staticmethod
    def _check(rate_hz) -> float:
        if isinstance(rate_hz, bool) or not isinstance(rate_hz, numbers.Real) \
                or not math.isfinite(rate_hz) or not 0.0 <= rate_hz <= MAX_RATE_HZ:
            raise ValueError(f"rate_hz must be a number in [0, {MAX_RATE_HZ:g}] (0 = off), got "
                             f"{rate_hz!r}")
        return float(rate_hz)

    @property
    def rate_hz(self) -> float:
        return self._rate

    def set_rate(self, rate_hz: float) -> None:
        """Change the rate; the new schedule starts at the next sample (which is due at
        once)."""
        self._rate = self._check(rate_hz)
        self.reset()

    def reset(self) -> None:
        """Forget the schedule: the next ``take`` is True (unless the rate is 0)."""
        self._t0_us = self._next_us = None

    @property
    def next_due_us(self) -> int | None:
        """Simulated time (us) of the next due sample; None before the first sample (due at
        once) and when the rate is 0."""
        return None if self._rate == 0.0 else self._next_us

    def due(self, t_us: int) -> bool:
        """Whether a sample is due at ``t_us`` (does not consume it)."""
        if self._rate == 0.0:
            return False
        return self._next_us is None or int(t_us) >= self._next_us or int(t_us) < self._t0_us

    def take(self, t_us: int) -> bool:
        """True if a sample is due at ``t_us``, and schedule the next one; else False.

        If time goes backwards (a reset simulation), the grid is re-anchored at ``t_us``.
        """
        if not self.due(t_us):
            return False
        t_us = int(t_us)
        if self._t0_us is None or t_us < self._t0_us:
            self._t0_us = t_us
        period = 1e6 / self._rate
        k = math.floor((t_us - self._t0_us) / period + 1e-9)  # the slot t_us falls in
        self._next_us = self._t0_us + math.ceil((k + 1) * period - 1e-6)
        return True
