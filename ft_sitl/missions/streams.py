"""A trial's random streams: one table of them, each seeded from the spec.

Every source of randomness in a trial draws from its own stream, keyed by numpy
``SeedSequence`` entropy made of the spec's ``seed`` and ``trial`` and the stream's number,
so that switching one source on (wind, say) leaves every other stream as it was. The
moving obstacles are the exception: they are scenario content, keyed by the scenario and
the trial number only (:func:`mover_key`).
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from types import MappingProxyType

import numpy as np

#: stream name -> its number after (seed, trial) in the entropy (the navigator's has none)
STREAMS = MappingProxyType({"navigator": (), "camera": (1,), "wind": (2,), "actuators": (3,),
                            "perception": (4,), "estimator": (5,)})


@dataclass(frozen=True)
class RandomStreams:
    """The entropy of each stream (``keys``: name -> tuple of integers). :meth:`rng` makes
    a fresh generator of a stream, :meth:`seed` the one integer the physics' seeded
    components take."""

    keys: MappingProxyType

    def entropy(self, name: str) -> tuple[int, ...]:
        return self.keys[name]

    def rng(self, name: str):
        return np.random.default_rng(np.random.SeedSequence(list(self.keys[name])))

    def seed(self, name: str) -> int:
        return int(np.random.SeedSequence(list(self.keys[name])).generate_state(1)[0])


def trial_streams(seed: int, trial: int) -> RandomStreams:
    """The streams of trial ``trial`` of a campaign seeded ``seed``."""
    return RandomStreams(MappingProxyType({name: (seed, trial, *suffix)
                                           for name, suffix in STREAMS.items()}))


def mover_key(where: str, scenario_seed: int, scenario_index: int, trial: int) -> tuple:
    """The entropy of a trial's moving obstacles: a function of the scenario (``where``:
    its family or file, its configuration and seed) and the trial number only, so every
    algorithm and platform flying trial ``trial`` of a configuration meets the same movers
    (a paired comparison). The campaign's ``seed`` does not change them; the scenario
    seed does."""
    key = int.from_bytes(hashlib.sha256(where.encode()).digest()[:4], "little")
    return (scenario_seed, key, scenario_index, trial, 6)


def mover_seed(where: str, scenario_seed: int, scenario_index: int, trial: int) -> int:
    """The integer seed of :func:`mover_key`'s stream (what scenarios.movers takes)."""
    return int(np.random.SeedSequence(list(mover_key(where, scenario_seed, scenario_index,
                                                     trial))).generate_state(1)[0])


def legacy_wire_streams(streams: RandomStreams, seed: int, trial: int) -> RandomStreams:
    """What a trial flown over MAVLink drew from up to protocol 8: the navigator's stream
    seeded by one integer drawn from its in-process entropy (the same generator only in
    name), and the bus camera's noise from (seed + 1000 trial, 7). Kept so that wire rows
    of those versions re-fly as they were made."""
    nav = int(np.random.SeedSequence(list(streams.keys["navigator"])).generate_state(1)[0])
    keys = dict(streams.keys, navigator=(nav,), camera=(seed + 1000 * trial, 7))
    return RandomStreams(MappingProxyType(keys))
