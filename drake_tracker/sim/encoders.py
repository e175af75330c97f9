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
from pydrake.systems.framework import LeafSystem

from drake_tracker.sim.bias import JointBiasModel
from drake_tracker.sim.scenario.config import EncoderConfig
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
    Discrete state, four groups: the sample index (-1 before any), and the three outputs
    (each output port is its group, read without a Python call: the recorder and the
    tracker read them at every sample).
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
        self._index = self.DeclareDiscreteState([-1.0])
        self._time = self.DeclareDiscreteState([-1.0])
        self._reading = self.DeclareDiscreteState(np.zeros(n))
        self._bias_state = self.DeclareDiscreteState(np.zeros(n))
        self._true_position = self.DeclareVectorInputPort("true_position", n)
        self.DeclareStateOutputPort("measured_position", self._reading)
        self.DeclareStateOutputPort("measurement_time", self._time)
        self.DeclareStateOutputPort("bias", self._bias_state)
        self.DeclarePeriodicDiscreteUpdateEvent(self._period, 0.0, self._update)

    @property
    def joint_names(self) -> list[str]:
        """The measured joints, in reading order."""
        return list(self._names)

    def _update(self, context, discrete_state):
        # One read of the discrete values and one writable view per group: the update
        # runs 1000 times a simulated second, and each pydrake call costs about 1 µs.
        state = context.get_discrete_state()
        index = round(float(state.get_value(self._index)[0])) + 1
        previous_t = float(state.get_value(self._time)[0])
        previous_bias = state.get_value(self._bias_state)
        n = self._n
        t = context.get_time()
        true_q = self._true_position.Eval(context)
        draws = self._normals(index, 2 * n)
        dt = max(t - previous_t, 0.0) if index > 0 else None
        bias = self._bias.next(previous_bias, t, dt, draws[n:])
        reading = quantize(true_q + bias + self._noise_rad * draws[:n], self._quant_rad)
        discrete_state.get_mutable_value(self._index)[0] = index
        discrete_state.get_mutable_value(self._time)[0] = t
        discrete_state.get_mutable_value(self._reading)[:] = reading
        discrete_state.get_mutable_value(self._bias_state)[:] = bias
