"""Encoder bias models: pure functions of time (and, for the random walk, of draws).

Every biased joint follows ``EncoderConfig.bias`` unless ``bias_profiles`` gives it its
own :class:`~drake_tracker.sim.scenario.config.BiasProfile`. The models (deg in the configs, rad
here):

* ``none``: 0; ``constant``: a fixed value;
* ``ramp``: ``from`` before ``start``, linear to ``value`` over ``duration``, then held;
* ``steps`` (``EncoderConfig``): ``+-step_amplitude_deg``, sign changes every
  ``step_period_s`` with a cosine transition of ``step_transition_s``; joint k of the
  biased joints starts with sign ``(-1)^k``;
* ``steps`` (a profile): the value becomes ``step_values[i]`` at ``step_times[i]`` (0
  before the first), each change a half-cosine of ``step_transition_s`` centred there;
* ``random-walk``: ``b(t_k) = b(t_{k-1}) + N(drift dt, sigma^2 dt)``, ``b(0) = 0``, so
  the variance grows as ``sigma^2 t``.
"""

from __future__ import annotations

import numpy as np

from drake_tracker.sim.scenario.config import BiasProfile, EncoderConfig
from drake_tracker.sim.scenario.validation import require


def constant_bias(times_s: np.ndarray, num_joints: int, bias_rad: float) -> np.ndarray:
    """(T, n) constant bias."""
    return np.full((len(np.atleast_1d(times_s)), num_joints), float(bias_rad))


def step_sign(times_s: np.ndarray, period_s: float, transition_s: float) -> np.ndarray:
    """A smooth square wave: +1 on [0, period), -1 on [period, 2 period), ..., each change
    a half-cosine of ``transition_s`` centred on the multiple of ``period_s``."""
    t = np.atleast_1d(np.asarray(times_s, float))
    k = np.floor(t / period_s)
    sign = np.where(k % 2 == 0, 1.0, -1.0)
    if transition_s <= 0:
        return sign
    # Distance to the nearest change point (at multiples of period_s, except 0).
    nearest = np.maximum(np.round(t / period_s), 1.0)
    x = (t - nearest * period_s) / transition_s  # in [-0.5, 0.5] inside a transition
    inside = np.abs(x) < 0.5
    before = np.where(nearest % 2 == 1, 1.0, -1.0)  # sign just before change `nearest`
    smooth = before * np.cos(np.pi * (x + 0.5))  # +before at x=-0.5, -before at x=+0.5
    return np.where(inside, smooth, sign)


def step_bias(times_s: np.ndarray, num_joints: int, amplitude_rad: float, period_s: float,
              transition_s: float) -> np.ndarray:
    """(T, n) smooth steps of alternating sign; joint k starts with sign (-1)^k."""
    s = step_sign(times_s, period_s, transition_s)
    signs = np.where(np.arange(num_joints) % 2 == 0, 1.0, -1.0)
    return amplitude_rad * np.outer(s, signs)


def ramp_bias(times_s: np.ndarray, from_rad: float, to_rad: float, start_s: float,
              duration_s: float) -> np.ndarray:
    """(T,) ``from`` before ``start_s``, linear to ``to`` over ``duration_s``, then held."""
    t = np.atleast_1d(np.asarray(times_s, float))
    if duration_s <= 0:
        return np.where(t >= start_s, to_rad, from_rad).astype(float)
    fraction = np.clip((t - start_s) / duration_s, 0.0, 1.0)
    return from_rad + (to_rad - from_rad) * fraction


def listed_steps_bias(times_s: np.ndarray, step_times_s: list[float],
                      step_values_rad: list[float], transition_s: float) -> np.ndarray:
    """(T,) 0 before the first step, ``step_values_rad[i]`` after ``step_times_s[i]``;
    each change a half-cosine of ``transition_s`` centred on its time."""
    t = np.atleast_1d(np.asarray(times_s, float))
    out = np.zeros(len(t))
    previous = 0.0
    for time, value in zip(step_times_s, step_values_rad):
        if transition_s > 0:
            y = np.clip((t - time) / transition_s + 0.5, 0.0, 1.0)
            blend = 0.5 - 0.5 * np.cos(np.pi * y)
        else:
            blend = (t >= time).astype(float)
        out += (value - previous) * blend
        previous = value
    return out


def profile_bias(profile: BiasProfile, times_s: np.ndarray) -> np.ndarray:
    """(T,) bias (rad) of a time-only profile; zeros for ``none`` and ``random-walk``."""
    t = np.atleast_1d(np.asarray(times_s, float))
    if profile.kind == "constant":
        return np.full(len(t), np.radians(profile.value_deg))
    if profile.kind == "ramp":
        return ramp_bias(t, np.radians(profile.ramp_from_deg), np.radians(profile.value_deg),
                         profile.ramp_start_s, profile.ramp_duration_s)
    if profile.kind == "steps":
        return listed_steps_bias(t, profile.step_times_s, np.radians(profile.step_values_deg),
                                 profile.step_transition_s)
    return np.zeros(len(t))


def deterministic_bias(config: EncoderConfig, times_s: np.ndarray, num_joints: int) -> np.ndarray:
    """(T, n) bias of ``config.bias`` for the time-only models (none, constant, steps,
    ramp); zeros for random-walk."""
    t = np.atleast_1d(np.asarray(times_s, float))
    if config.bias == "constant":
        return constant_bias(t, num_joints, np.radians(config.constant_bias_deg))
    if config.bias == "steps":
        return step_bias(t, num_joints, np.radians(config.step_amplitude_deg),
                         config.step_period_s, config.step_transition_s)
    if config.bias == "ramp":
        ramp = ramp_bias(t, 0.0, np.radians(config.constant_bias_deg), config.ramp_start_s,
                         config.ramp_duration_s)
        return np.repeat(ramp[:, None], num_joints, axis=1)
    return np.zeros((len(t), num_joints))


class JointBiasModel:
    """The bias of every measured joint: ``config.bias`` on ``biased_joints`` (those
    without a profile), each profile on its joint, 0 elsewhere."""

    def __init__(self, config: EncoderConfig, joint_names: list[str],
                 biased_joints: list[str]):
        names = list(joint_names)
        for name in list(biased_joints) + list(config.bias_profiles):
            require(name in names, "encoders.biased_joints / bias_profiles", name,
                    f"is not a measured joint; measured joints: {names}")
        self._config = config
        self._n = len(names)
        self._shared = np.array([names.index(b) for b in biased_joints
                                 if b not in config.bias_profiles], int)
        self._profiles = {names.index(j): p for j, p in config.bias_profiles.items()}
        self.random_walk_sigma = np.zeros(self._n)  # rad / sqrt(s)
        self.random_walk_drift = np.zeros(self._n)  # rad / s
        if config.bias == "random-walk":
            self.random_walk_sigma[self._shared] = np.radians(
                config.random_walk_sigma_deg_per_sqrt_s)
        for j, p in self._profiles.items():
            if p.kind == "random-walk":
                self.random_walk_sigma[j] = np.radians(p.random_walk_sigma_deg_per_sqrt_s)
                self.random_walk_drift[j] = np.radians(p.random_walk_drift_deg_per_s)
        self.is_random_walk = np.zeros(self._n, bool)
        if config.bias == "random-walk":
            self.is_random_walk[self._shared] = True
        for j, p in self._profiles.items():
            self.is_random_walk[j] = p.kind == "random-walk"
        self._any_random_walk = bool(self.is_random_walk.any())
        #: The time-only part when no model depends on time (none, constant, random-walk
        #: everywhere): computed once, not at every sample.
        steady = ("none", "constant", "random-walk")
        self._fixed = None
        if config.bias in steady and all(p.kind in steady for p in self._profiles.values()):
            self._fixed = self._deterministic(0.0)
            self._fixed.flags.writeable = False

    def deterministic(self, t: float) -> np.ndarray:
        """(n,) the time-only part of the bias at ``t`` (0 on random-walk joints)."""
        if self._fixed is not None:
            return self._fixed.copy()
        return self._deterministic(t)

    def _deterministic(self, t: float) -> np.ndarray:
        bias = np.zeros(self._n)
        if len(self._shared) and self._config.bias != "random-walk":
            bias[self._shared] = deterministic_bias(self._config, [t], len(self._shared))[0]
        for j, p in self._profiles.items():
            bias[j] = profile_bias(p, [t])[0]
        return bias

    def next(self, previous: np.ndarray, t: float, dt: float | None,
             draws: np.ndarray) -> np.ndarray:
        """(n,) bias at sample time ``t``: the random walk steps from ``previous`` by
        ``dt`` with the standard normals ``draws`` (n,); ``dt`` None = the first sample."""
        bias = self.deterministic(t)
        if not self._any_random_walk:
            return bias
        walk = np.array(previous, float, copy=True)
        if dt is not None:
            w = self.is_random_walk
            walk[w] += (self.random_walk_sigma[w] * np.sqrt(dt) * draws[w]
                        + self.random_walk_drift[w] * dt)
        return np.where(self.is_random_walk, walk, bias)
