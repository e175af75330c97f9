"""A 1 kHz stream of time stamps with every awkwardness a real clock has, for the tests
of the time-stamp policy (seeded)."""

import numpy as np


def awkward_stamps(seed: int, count: int = 6000) -> list[float]:
    """Jitter, repeats, small steps back, glitches far in the future, steps that stay
    (forward by more and less than 0.02 s, and back), NaN and inf."""
    rng = np.random.default_rng(seed)
    raw, t, offset = [], 0.0, 0.0
    for _ in range(count):
        t += 1e-3 + rng.normal(0.0, 1e-4)
        event = rng.random()
        if event < 0.003:
            offset += rng.choice([-2.0, -0.05, 0.015, 0.05, 40.0])  # a step that stays
        stamp = t + offset
        if event > 0.995:
            stamp += rng.choice([1000.0, 0.03, -0.002, np.nan, np.inf])  # one glitch
        elif event > 0.99:
            stamp = raw[-1] if raw else stamp  # a repeated stamp
        raw.append(stamp)
    return raw
