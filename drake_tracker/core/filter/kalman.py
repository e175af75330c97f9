"""A bank of independent 2-state Kalman filters on (angle, bias), one per joint.

Models (paper eqs. 3-5, docs/method.md §2-3), with Δ the time step in seconds:

* encoder:  ``q = a + b + N(0, σq²)``
* angle:    ``a(t+Δ) = a(t) + N(0, Δ σa²)``
* bias:     ``b(t+Δ) = c^Δ b(t) + N(0, Δ σb²)``

A belief is a ``(5, n)`` array of per-joint moments, rows ``MEAN_A, MEAN_B, VAR_A,
COV_AB, VAR_B``; everything is vectorised over joints and the hot step is one numba call.
A joint without bias has ``σb = 0`` and starts with zero bias variance, so its bias stays 0.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

MEAN_A, MEAN_B, VAR_A, COV_AB, VAR_B = range(5)
#: Rows of a bank's coefficients (``JointKalmanBank._coef``).
_SA2, _SB2, _LOG_C, _SQ2, _CAP = range(5)


@dataclass(frozen=True)
class KalmanBankParams:
    """Per-joint noise parameters as arrays of length n (SI units, per second).

    ``encoder_noise_std`` σq (rad), ``angle_process_std`` σa (rad/√s),
    ``bias_process_std`` σb (rad/√s), ``bias_decay_per_s`` c in (0, 1] (the fraction
    of the bias left after one second), ``has_bias`` (bool).
    """

    encoder_noise_std: np.ndarray
    angle_process_std: np.ndarray
    bias_process_std: np.ndarray
    bias_decay_per_s: np.ndarray
    has_bias: np.ndarray
    names: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        n = len(self.encoder_noise_std)
        label = (lambda i: self.names[i]) if len(self.names) == n else (lambda i: f"#{i}")
        for field in ("encoder_noise_std", "angle_process_std", "bias_process_std",
                      "bias_decay_per_s", "has_bias"):
            value = np.asarray(getattr(self, field))
            if value.shape != (n,):
                raise ValueError(
                    f"KalmanBankParams.{field} has shape {value.shape}, expected ({n},)")
        checks = (
            ("encoder_noise_std", lambda v: np.isfinite(v) & (v > 0), "must be finite and > 0"),
            ("angle_process_std", lambda v: np.isfinite(v) & (v > 0), "must be finite and > 0"),
            ("bias_process_std", lambda v: np.isfinite(v) & (v >= 0), "must be finite and >= 0"),
            ("bias_decay_per_s", lambda v: (v > 0) & (v <= 1), "must be in (0, 1]"),
        )
        for field, ok, why in checks:
            value = np.asarray(getattr(self, field), float)
            bad = np.flatnonzero(~ok(value))
            if bad.size:
                i = int(bad[0])
                raise ValueError(f"{field} of joint {label(i)} is {value[i]}: {why}")
        biased_without_noise = np.flatnonzero(
            np.asarray(self.has_bias, bool) & (np.asarray(self.bias_process_std) <= 0))
        if biased_without_noise.size:
            i = int(biased_without_noise[0])
            raise ValueError(f"bias_process_std of joint {label(i)} must be > 0 for a biased joint")

    @property
    def num_joints(self) -> int:
        """n, the number of joints (the length of ``encoder_noise_std``)."""
        return len(self.encoder_noise_std)

    def effective_bias_std(self) -> np.ndarray:
        """σb with non-biased joints forced to 0."""
        return np.where(np.asarray(self.has_bias, bool), self.bias_process_std, 0.0)

    def stationary_bias_variance(self, dt: float) -> np.ndarray:
        """Eq. (8): the bias variance a bank predicting in steps of ``dt`` tends to."""
        c2 = np.asarray(self.bias_decay_per_s, float) ** (2.0 * dt)
        with np.errstate(divide="ignore"):
            return np.where(c2 < 1.0, dt * self.effective_bias_std() ** 2 / (1.0 - c2), np.inf)


def initial_moments(mean_angle: np.ndarray, angle_std: np.ndarray, bias_std: np.ndarray,
                    has_bias: np.ndarray) -> np.ndarray:
    """A (5, n) belief: independent angle and bias, bias mean 0 (0 variance where no bias)."""
    n = len(mean_angle)
    m = np.zeros((5, n))
    m[MEAN_A] = mean_angle
    m[VAR_A] = np.asarray(angle_std, float) ** 2
    m[VAR_B] = np.where(np.asarray(has_bias, bool), np.asarray(bias_std, float) ** 2, 0.0)
    return m


@numba.njit(cache=True)
def _predict_inplace(m, dt, sa2, sb2, log_c):
    for j in range(m.shape[1]):
        cd = np.exp(log_c[j] * dt)
        m[MEAN_B, j] *= cd
        m[VAR_A, j] += dt * sa2[j]
        m[COV_AB, j] *= cd
        m[VAR_B, j] = cd * cd * m[VAR_B, j] + dt * sb2[j]


@numba.njit(cache=True)
def _update_inplace(m, q, sq2):
    for j in range(m.shape[1]):
        if q[j] != q[j]:  # NaN: this joint's encoder gave no value; it is only predicted
            continue
        saa = m[VAR_A, j]
        sab = m[COV_AB, j]
        sbb = m[VAR_B, j]
        s = saa + 2.0 * sab + sbb + sq2[j]
        ka = (saa + sab) / s
        kb = (sab + sbb) / s
        innovation = q[j] - m[MEAN_A, j] - m[MEAN_B, j]
        m[MEAN_A, j] += ka * innovation
        m[MEAN_B, j] += kb * innovation
        # Covariance P - K S K^T, written so that it stays symmetric by construction.
        m[VAR_A, j] = max(saa - ka * ka * s, 0.0)
        m[COV_AB, j] = sab - ka * kb * s
        m[VAR_B, j] = max(sbb - kb * kb * s, 0.0)


@numba.njit(cache=True)
def _cap_missing_inplace(m, q, cap):
    """A joint without a value (NaN) keeps its angle variance at most ``cap`` (and its
    angle-bias covariance within the Cauchy-Schwarz bound of the capped variance)."""
    for j in range(m.shape[1]):
        if q[j] == q[j] or m[VAR_A, j] <= cap[j]:
            continue
        m[VAR_A, j] = cap[j]
        bound = np.sqrt(cap[j] * m[VAR_B, j])
        m[COV_AB, j] = min(max(m[COV_AB, j], -bound), bound)


@numba.njit(cache=True)
def _step_inplace(m, dt, q, coef):
    """Predict by ``dt``, then update with ``q``; ``coef`` is the bank's (5, n) rows
    σa², σb², log c, σq² and the missing joints' cap (one array: each argument of a
    compiled call costs, most when the caches are cold, as at 1000 readings a second)."""
    if dt > 0.0:
        _predict_inplace(m, dt, coef[_SA2], coef[_SB2], coef[_LOG_C])
    _cap_missing_inplace(m, q, coef[_CAP])
    _update_inplace(m, q, coef[_SQ2])


class JointKalmanBank:
    """The Kalman bank for fixed parameters. Beliefs are (5, n) arrays; steps copy them.

    A reading may lack some joints (NaN: that encoder gave no value): those joints are
    predicted, not updated, and their angle variance grows no wider than
    ``missing_angle_var`` (n,) (default: unbounded). The tracker bounds it at the start's
    angle variance (``core/filter/start.py``): the angle random walk σa is large so that
    the angle follows its encoder; without one it would put a radians-wide prior on the
    joint within milliseconds, and the image update could not search it.
    """

    def __init__(self, params: KalmanBankParams, missing_angle_var: np.ndarray | None = None):
        self.params = params
        n = params.num_joints
        self._coef = np.empty((5, n))
        self._coef[_CAP] = (np.inf if missing_angle_var is None
                            else np.asarray(missing_angle_var, float).reshape(n))
        self._coef[_SA2] = np.asarray(params.angle_process_std, float) ** 2
        self._coef[_SB2] = params.effective_bias_std().astype(float) ** 2
        self._coef[_LOG_C] = np.log(np.asarray(params.bias_decay_per_s, float))
        self._coef[_SQ2] = np.asarray(params.encoder_noise_std, float) ** 2
        self._views()

    def _views(self) -> None:
        """The rows of ``_coef`` by name."""
        self._sa2, self._sb2, self._log_c, self._sq2, self._cap = self._coef

    @property
    def num_joints(self) -> int:
        """n, the number of joints of ``params``."""
        return self.params.num_joints

    @property
    def bias_process_var(self) -> np.ndarray:
        """σb² (n,), the bias variance rate (rad²/s) the process model (5) uses."""
        return self._sb2.copy()

    def check_reading(self, reading: np.ndarray) -> np.ndarray:
        """``reading`` as a float (n,) array; a ValueError for a wrong shape, for no value
        at all, or naming the joints whose value is infinite (NaN: no value, allowed)."""
        reading = np.asarray(reading, dtype=float)
        if reading.shape != (self.num_joints,):
            raise ValueError(
                f"joint reading has shape {reading.shape}, expected ({self.num_joints},)")
        if reading.size and math.isfinite(sum(reading.tolist())):
            return reading  # every value finite (a NaN or ±inf would make the sum one)
        if np.isinf(reading).any():
            bad = [self.params.names[i] if self.params.names else str(i)
                   for i in np.flatnonzero(np.isinf(reading))]
            raise ValueError(f"joint reading is infinite for joints {bad}")
        if np.isnan(reading).all() and reading.size:
            raise ValueError("joint reading has no value (all NaN)")
        return reading

    def predict(self, moments: np.ndarray, dt: float) -> np.ndarray:
        """Moments after ``dt`` seconds of the process models (4) and (5)."""
        if dt < 0:
            raise ValueError(f"cannot predict backwards in time (dt = {dt} s)")
        out = moments.copy()
        if dt > 0:
            _predict_inplace(out, float(dt), self._sa2, self._sb2, self._log_c)
        return out

    def update(self, moments: np.ndarray, reading: np.ndarray) -> np.ndarray:
        """Moments after an encoder reading (model 3)."""
        out = moments.copy()
        reading = self.check_reading(reading)
        _cap_missing_inplace(out, reading, self._cap)
        _update_inplace(out, reading, self._sq2)
        return out

    def step(self, moments: np.ndarray, dt: float, reading: np.ndarray) -> np.ndarray:
        """Predict by ``dt`` then update with ``reading``; the per-reading hot path."""
        if dt < 0:
            raise ValueError(f"cannot predict backwards in time (dt = {dt} s)")
        out = moments.copy()
        _step_inplace(out, float(dt), self.check_reading(reading), self._coef)
        return out

    def step_unchecked(self, moments: np.ndarray, dt: float, reading: np.ndarray) -> np.ndarray:
        """``step`` for readings that were already checked (replays of the buffer)."""
        out = moments.copy()
        _step_inplace(out, dt, reading, self._coef)
        return out

    def step_in_place(self, moments: np.ndarray, dt: float, reading: np.ndarray) -> None:
        """``step_unchecked`` into ``moments`` itself, a writeable (5, n) float array that
        nothing else holds (the Kalman bank system's copy of its discrete state)."""
        _step_inplace(moments, dt, reading, self._coef)


def recombine_with_bias(moments: np.ndarray, mean_post: np.ndarray,
                        var_post: np.ndarray) -> np.ndarray:
    """Eq. (16): new angle marginals (μ', s') combined with p(b | a) from the prior.

    ``M = Sab/Saa``, ``m = μb - M μa``, ``C = Sbb - Sab²/Saa``; the result has mean
    ``[μ', M μ' + m]`` and covariance ``[[s', M s'], [M s', C + M² s']]``.
    """
    out = moments.copy()
    saa = moments[VAR_A]
    safe = saa > 0
    M = np.where(safe, moments[COV_AB] / np.where(safe, saa, 1.0), 0.0)
    m = moments[MEAN_B] - M * moments[MEAN_A]
    C = np.maximum(moments[VAR_B] - M * moments[COV_AB], 0.0)
    out[MEAN_A] = mean_post
    out[MEAN_B] = M * mean_post + m
    out[VAR_A] = var_post
    out[COV_AB] = M * var_post
    out[VAR_B] = C + M * M * var_post
    return out
