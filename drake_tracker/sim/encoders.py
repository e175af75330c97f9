"""Biased, noisy joint encoders as a Drake LeafSystem.

A reading of joint j at sample k (time ``t_k = k / rate_hz``) is
``q_j = quantize(a_j(t_k) + b_j(t_k) + N(0, sigma^2))``, with the bias ``b`` of
:mod:`drake_tracker.sim.bias` (constant, steps, ramp, random walk; per joint with
``bias_profiles``).

All randomness of sample k is drawn from a counter-based generator keyed by
``(seed, k)`` (``drake_tracker.sim.streams``), so runs are reproducible and contexts
copy and reset correctly.
"""

from __future__ import annotations

import numpy as np
from pydrake.systems.framework import BasicVector, LeafSystem

from drake_tracker.sim.bias import JointBiasModel
from drake_tracker.sim.config import EncoderConfig
from drake_tracker.sim.streams import CounterNormals, sample_normals

__all__ = ["BiasedEncoders", "quantize", "sample_normals"]


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
        self._seed = int(seed)
        self._normals = CounterNormals(self._seed)  # sample_normals(seed, k, .), faster
        self._period = 1.0 / config.rate_hz
        biased = list(config.biased_joints) if biased_joints is None else list(biased_joints)
        self._bias = JointBiasModel(config, self._names, biased)
        self._noise_rad = np.radians(config.noise_sigma_deg)
        self._quant_rad = np.radians(config.quantization_deg)
        initial = np.zeros(2 + 2 * n)
        initial[0] = -1.0
        initial[1] = -1.0
        self._state = self.DeclareDiscreteState(initial)
        self._true_position = self.DeclareVectorInputPort("true_position", n)
        self.DeclareVectorOutputPort("measured_position", n, self._calc_measured,
                                     {self.discrete_state_ticket(self._state)})
        self.DeclareVectorOutputPort("measurement_time", 1, self._calc_time,
                                     {self.discrete_state_ticket(self._state)})
        self.DeclareVectorOutputPort("bias", n, self._calc_bias,
                                     {self.discrete_state_ticket(self._state)})
        self.DeclarePeriodicDiscreteUpdateEvent(self._period, 0.0, self._update)

    @property
    def joint_names(self) -> list[str]:
        """The measured joints, in reading order."""
        return list(self._names)

    def _update(self, context, discrete_state):
        x = context.get_discrete_state(self._state).get_value()
        n = self._n
        index = int(round(x[0])) + 1
        t = context.get_time()
        true_q = self._true_position.Eval(context)
        draws = self._normals(index, 2 * n)
        dt = max(t - x[1], 0.0) if index > 0 else None
        bias = self._bias.next(x[2 + n:], t, dt, draws[n:])
        reading = quantize(true_q + bias + self._noise_rad * draws[:n], self._quant_rad)
        out = discrete_state.get_mutable_vector(self._state).get_mutable_value()
        out[0], out[1] = index, t
        out[2:2 + n] = reading
        out[2 + n:] = bias

    def _calc_measured(self, context, output: BasicVector):
        x = context.get_discrete_state(self._state).get_value()
        output.SetFromVector(x[2:2 + self._n])

    def _calc_time(self, context, output: BasicVector):
        output.SetAtIndex(0, context.get_discrete_state(self._state).get_value()[1])

    def _calc_bias(self, context, output: BasicVector):
        x = context.get_discrete_state(self._state).get_value()
        output.SetFromVector(x[2 + self._n:])
