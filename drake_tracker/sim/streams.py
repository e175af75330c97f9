"""Counter-based random streams: draws that depend only on (seed, stream, index).

Every random number of the simulated world comes from here, so runs are reproducible
and a Context copied or reset draws the same numbers. Streams in use: 0 the encoders'
noise and random walk, 7 the camera's pixels, 8 the camera's clock, 9 the world
robot's mismatch.
"""

from __future__ import annotations

import numpy as np


def counter_generator(seed: int, index: int, stream: int = 0) -> np.random.Generator:
    """A generator whose draws depend only on (seed, stream, index): counter-based Philox.

    The index sits in the second counter word and Philox increments the first, so the
    draws of index k never overlap those of index k+1 (up to 2^64 blocks per index).
    """
    bitgen = np.random.Philox(key=np.array([int(seed), int(stream)], np.uint64),
                              counter=np.array([0, int(index), 0, 0], np.uint64))
    return np.random.Generator(bitgen)


def sample_normals(seed: int, index: int, size: int, stream: int = 0) -> np.ndarray:
    """Standard normals that depend only on (seed, stream, index); see counter_generator."""
    return counter_generator(seed, index, stream).standard_normal(size)


class CounterNormals:
    """``sample_normals(seed, index, size, stream)`` for one (seed, stream), many indices:
    the same draws, from one Philox whose state is set to what ``counter_generator``
    builds (counter [0, index, 0, 0], key [seed, stream], no buffered draws), without
    building a generator (and seeding it from the OS) per index, as the encoders would
    1000 times a simulated second. Not for concurrent use from two threads."""

    def __init__(self, seed: int, stream: int = 0):
        self._bitgen = np.random.Philox(key=np.array([int(seed), int(stream)], np.uint64))
        self._generator = np.random.Generator(self._bitgen)
        self._counter = [0, 0, 0, 0]
        self._state = {"bit_generator": "Philox",
                       "state": {"counter": self._counter, "key": [int(seed), int(stream)]},
                       "buffer": [0, 0, 0, 0], "buffer_pos": 4, "has_uint32": 0,
                       "uinteger": 0}

    def __call__(self, index: int, size: int) -> np.ndarray:
        """(size,) standard normals of ``index``."""
        self._counter[1] = int(index)
        self._bitgen.state = self._state
        return self._generator.standard_normal(size)
