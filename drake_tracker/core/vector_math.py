"""exp and log over arrays, written so that LLVM vectorises them (numba kernels).

numba calls libm's ``exp``/``log`` one value at a time (no vector math library is
available without Intel's SVML), so a loop that calls them cannot use SIMD. These
in-place versions use only multiplies, adds and integer bit operations on the float's
representation, which vectorise with AVX2:

* ``exp``: x = k ln2 + r with |r| <= ln2/2 (k by the round-to-nearest of adding
  1.5 * 2^52), e^r by its Taylor polynomial to degree 13 (truncation < 1e-17 relative),
  2^k built in the exponent bits;
* ``log``: y = 2^e m with m in [sqrt(1/2), sqrt(2)) from the bits, log m = 2 atanh(s),
  s = (m - 1)/(m + 1), by its series to s^23 (truncation < 1e-17).

Both agree with libm to a few ulps (tested). Domain, as the likelihood uses them:
``exp_inplace`` for x in [-700, 700] (arguments are clamped to it), ``log_inplace`` for
positive normal numbers.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

#: Adding this rounds a double of magnitude < 2^51 to an integer held in the low bits.
_MAGIC = 6755399441055744.0  # 1.5 * 2^52
_MAGIC_BITS = np.array([_MAGIC]).view(np.int64)[0]
_LOG2E = 1.0 / math.log(2.0)
_LN2_HI = 6.93147180369123816490e-01  # ln 2 split so that k * _LN2_HI is exact
_LN2_LO = 1.90821492927058770002e-10
_LN2 = math.log(2.0)
_SQRT_HALF_BITS = np.array([math.sqrt(0.5)]).view(np.int64)[0]
_MANTISSA_MASK = (1 << 52) - 1
_EXP_DEGREE = 13
_EXP_COEFFS = tuple(1.0 / math.factorial(k) for k in range(_EXP_DEGREE + 1))
_LOG_COEFFS = tuple(2.0 / (2 * k + 1) for k in range(12))  # 2 atanh(s) = sum c_k s^(2k+1)
_SAFE = {"nsz", "arcp", "contract", "afn"}


@njit(cache=True, fastmath=_SAFE)
def exp_inplace(x: np.ndarray, count: int, work: np.ndarray) -> None:
    """x[:count] = exp(x[:count]), x clamped to [-700, 700] first. ``work``: float64
    scratch of at least ``count`` elements."""
    bits = work.view(np.int64)
    for i in range(count):
        v = min(max(x[i], -700.0), 700.0)
        t = v * _LOG2E + _MAGIC
        work[i] = t
        k = t - _MAGIC
        r = (v - k * _LN2_HI) - k * _LN2_LO
        p = _EXP_COEFFS[13]
        p = p * r + _EXP_COEFFS[12]
        p = p * r + _EXP_COEFFS[11]
        p = p * r + _EXP_COEFFS[10]
        p = p * r + _EXP_COEFFS[9]
        p = p * r + _EXP_COEFFS[8]
        p = p * r + _EXP_COEFFS[7]
        p = p * r + _EXP_COEFFS[6]
        p = p * r + _EXP_COEFFS[5]
        p = p * r + _EXP_COEFFS[4]
        p = p * r + _EXP_COEFFS[3]
        p = p * r + _EXP_COEFFS[2]
        p = p * r + _EXP_COEFFS[1]
        x[i] = p * r + _EXP_COEFFS[0]
    for i in range(count):
        bits[i] = (bits[i] - _MAGIC_BITS + 1023) << 52
    for i in range(count):
        x[i] = x[i] * work[i]


@njit(cache=True, fastmath=_SAFE)
def log_inplace(y: np.ndarray, count: int, work: np.ndarray) -> None:
    """y[:count] = log(y[:count]) for positive normal y. ``work``: float64 scratch of at
    least ``count`` elements."""
    ybits = y.view(np.int64)
    wbits = work.view(np.int64)
    for i in range(count):
        shifted = ybits[i] - _SQRT_HALF_BITS
        wbits[i] = (shifted >> 52) + _MAGIC_BITS  # the exponent e, as _MAGIC + e
        ybits[i] = (shifted & _MANTISSA_MASK) + _SQRT_HALF_BITS  # m in [sqrt(1/2), sqrt 2)
    for i in range(count):
        e = work[i] - _MAGIC
        m = y[i]
        s = (m - 1.0) / (m + 1.0)
        s2 = s * s
        p = _LOG_COEFFS[11]
        p = p * s2 + _LOG_COEFFS[10]
        p = p * s2 + _LOG_COEFFS[9]
        p = p * s2 + _LOG_COEFFS[8]
        p = p * s2 + _LOG_COEFFS[7]
        p = p * s2 + _LOG_COEFFS[6]
        p = p * s2 + _LOG_COEFFS[5]
        p = p * s2 + _LOG_COEFFS[4]
        p = p * s2 + _LOG_COEFFS[3]
        p = p * s2 + _LOG_COEFFS[2]
        p = p * s2 + _LOG_COEFFS[1]
        p = p * s2 + _LOG_COEFFS[0]
        y[i] = e * _LN2 + s * p
