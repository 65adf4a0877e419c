"""How a navigator's computing time turns into simulated delay, shared by the planners
(:mod:`~ft_sitl.navigation.planners.skeleton`) and the learned navigators: the two
latency parameters and :class:`DelayedCommands`."""

from __future__ import annotations

import time

from ft_sitl.schema import Param

LATENCY = Param("latency_s", 0.01, "s", (0.0, 1.0),
                doc="a plan takes effect this long (simulated) after it was asked for: the "
                    "original's compute time on a desktop CPU")
MEASURED_LATENCY = Param("measured_latency", False,
                         doc="use this process's measured compute time instead of latency_s")

class DelayedCommands:
    """A command computed every ``1 / rate_hz`` s (simulated) from the observation of that
    moment and put in force ``latency_s`` later, or after its measured compute time with
    ``measured``: how the learned navigators (NavRL, learned) turn a policy's output into
    the setpoint of each step. ``compute_s`` keeps each computation's wall-clock time."""

    def __init__(self, rate_hz: float, latency_s: float, measured: bool):
        self.period = 1.0 / float(rate_hz)
        self.latency = float(latency_s)
        self.measured = bool(measured)
        self.next_t = 0.0
        self.current = None
        self.pending: tuple[float, object] | None = None
        self.compute_s: list[float] = []

    def step(self, t: float, compute):
        """The command in force at ``t``: a pending one whose time has come takes over;
        when a period is due, ``compute()`` gives the next (None: no new command). None
        before the first command is in force."""
        if self.pending is not None and t >= self.pending[0] - 1e-9:
            self.current, self.pending = self.pending[1], None
        if t >= self.next_t - 1e-9:
            self.next_t = t + self.period
            t0 = time.perf_counter()
            cmd = compute()
            dt = time.perf_counter() - t0
            self.compute_s.append(dt)
            if cmd is not None:
                lat = dt if self.measured else self.latency
                if lat <= 0.0:
                    self.current = cmd
                else:
                    self.pending = (t + lat, cmd)
        return self.current
