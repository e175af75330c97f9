"""Biased, noisy joint encoders: pure bias/noise models and a Drake LeafSystem.

A reading of joint j at sample k (time ``t_k = k / rate_hz``) is
``q_j = quantize(a_j(t_k) + b_j(t_k) + N(0, sigma^2))``, with the bias ``b`` from one of

* ``none``: 0;
* ``constant``: ``constant_bias_deg`` on every biased joint;
* ``steps``: smooth steps of alternating sign, ``+-step_amplitude_deg`` (so a jump is
  twice that), sign changes every ``step_period_s`` with a cosine transition of
  ``step_transition_s``; joint k of the biased joints starts with sign ``(-1)^k``;
* ``random-walk``: ``b(t_k) = b(t_{k-1}) + N(0, sigma_rw^2 (t_k - t_{k-1}))``, b(0) = 0,
  so the variance grows as ``sigma_rw^2 t``.

All randomness of sample k is drawn from a counter-based generator keyed by
``(seed, k)``, so runs are reproducible and contexts copy and reset correctly.
"""

from __future__ import annotations

import numpy as np
from pydrake.systems.framework import BasicVector, LeafSystem

from drake_tracker.sim.scenario import EncoderConfig


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


def deterministic_bias(config: EncoderConfig, times_s: np.ndarray, num_joints: int) -> np.ndarray:
    """(T, n) bias of the time-only models (none, constant, steps); zeros for random-walk."""
    t = np.atleast_1d(np.asarray(times_s, float))
    if config.bias == "constant":
        return constant_bias(t, num_joints, np.radians(config.constant_bias_deg))
    if config.bias == "steps":
        return step_bias(t, num_joints, np.radians(config.step_amplitude_deg),
                         config.step_period_s, config.step_transition_s)
    return np.zeros((len(t), num_joints))


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


def quantize(values: np.ndarray, step: float) -> np.ndarray:
    """Rounds to the nearest multiple of ``step``; ``step <= 0`` leaves values unchanged."""
    if step <= 0:
        return np.asarray(values, float)
    return step * np.round(np.asarray(values, float) / step)


class BiasedEncoders(LeafSystem):
    """Samples ``true_position`` at ``config.rate_hz`` and outputs biased, noisy readings.

    Ports: input ``true_position`` (n); outputs ``measured_position`` (n),
    ``measurement_time`` (1: the time stamp of the latest sample, -1 before any) and
    ``bias`` (n: the noise-free bias of that sample, ground truth).
    Discrete state: [sample index, sample time, readings (n), bias (n)].
    """

    def __init__(self, joint_names: list[str], config: EncoderConfig, seed: int = 0,
                 biased_joints: list[str] | None = None):
        super().__init__()
        self._names = list(joint_names)
        n = len(self._names)
        self._n = n
        self._config = config
        self._seed = int(seed)
        self._period = 1.0 / config.rate_hz
        biased = list(config.biased_joints) if biased_joints is None else list(biased_joints)
        for name in biased:
            if name not in self._names:
                raise ValueError(f"encoders.biased_joints: joint '{name}' is not measured; "
                                 f"measured joints: {self._names}")
        self._biased = np.array([self._names.index(b) for b in biased], int)
        self._noise_rad = np.radians(config.noise_sigma_deg)
        self._rw_rad = np.radians(config.random_walk_sigma_deg_per_sqrt_s)
        self._quant_rad = np.radians(config.quantization_deg)
        initial = np.zeros(2 + 2 * n)
        initial[0] = -1.0
        initial[1] = -1.0
        self._state = self.DeclareDiscreteState(initial)
        self.DeclareVectorInputPort("true_position", n)
        self.DeclareVectorOutputPort("measured_position", n, self._calc_measured,
                                     {self.discrete_state_ticket(self._state)})
        self.DeclareVectorOutputPort("measurement_time", 1, self._calc_time,
                                     {self.discrete_state_ticket(self._state)})
        self.DeclareVectorOutputPort("bias", n, self._calc_bias,
                                     {self.discrete_state_ticket(self._state)})
        self.DeclarePeriodicDiscreteUpdateEvent(self._period, 0.0, self._update)

    @property
    def joint_names(self) -> list[str]:
        return list(self._names)

    @property
    def biased_indices(self) -> np.ndarray:
        return self._biased.copy()

    def _update(self, context, discrete_state):
        x = context.get_discrete_state(self._state).get_value()
        n = self._n
        index = int(round(x[0])) + 1
        t = context.get_time()
        true_q = self.get_input_port(0).Eval(context)
        draws = sample_normals(self._seed, index, 2 * n)
        bias = np.zeros(n)
        if self._config.bias == "random-walk":
            bias = x[2 + n:].copy()
            if index > 0:
                dt = max(t - x[1], 0.0)
                bias[self._biased] += self._rw_rad * np.sqrt(dt) * draws[n + self._biased]
        elif len(self._biased):
            bias[self._biased] = deterministic_bias(self._config, [t], len(self._biased))[0]
        reading = quantize(true_q + bias + self._noise_rad * draws[:n], self._quant_rad)
        out = np.concatenate([[index, t], reading, bias])
        discrete_state.get_mutable_vector(self._state).SetFromVector(out)

    def _calc_measured(self, context, output: BasicVector):
        x = context.get_discrete_state(self._state).get_value()
        output.SetFromVector(x[2:2 + self._n])

    def _calc_time(self, context, output: BasicVector):
        output.SetAtIndex(0, context.get_discrete_state(self._state).get_value()[1])

    def _calc_bias(self, context, output: BasicVector):
        x = context.get_discrete_state(self._state).get_value()
        output.SetFromVector(x[2 + self._n:])
