"""LLVM IR for single-precision lanes: <8 x float> vectors (one AVX2 register, all
:data:`~drake_tracker.core.simd.lanes.LANES` particles of a batch), and exp, log and erfc at
float32 accuracy from multiplies, adds and bit operations.

The pixel likelihood (:mod:`drake_tracker.core.simd.lane_likelihood`) evaluates its mixture
in these: half the instructions of <8 x double> on AVX2, and polynomials of about half
the degree that double precision needs (the double-precision versions these replaced are
in git history, before d9a4b87). Nothing here is called at run time: these functions
emit IR.

Accuracy (tested against libm in ``tests/render/test_lanes.py``): exp and log within a few
float32 ulps (relative 1e-6, log relative to max(1, |log y|)); erfc within 1e-6 + 2e-7 x^2
relative on [-6, ERFC_Y_MAX_F32]: the erfcx fit (:func:`erfcx_fit_f32`, 2e-8), the
rounding of float32 arithmetic, and exp(-y^2)'s of y^2.
"""

from __future__ import annotations

import math

import numpy as np
from llvmlite import ir

from drake_tracker.core.simd.ir_f64 import intrinsic_call, vmax, vmin

#: Floats per vector: all lanes of a batch.
WIDTH_F32 = 8
F32 = ir.FloatType()
I32 = ir.IntType(32)
VEC_F32 = ir.VectorType(F32, WIDTH_F32)
IVEC_I32 = ir.VectorType(I32, WIDTH_F32)

#: erfc(y) for y in [0, ERFC_Y_MAX_F32] as exp(-y^2) erfcx(y), erfcx a polynomial in s
#: (:func:`erfcx_fit_f32`); erfc(9) = 4e-37 is near float32's least normal number (1.2e-38).
ERFC_Y_MAX_F32 = 9.0
_ERFCX_DEGREE = 10
_T_LO = 1.0 / (1.0 + 0.5 * ERFC_Y_MAX_F32)
#: exp's argument range: e^-87 and e^87 are normal float32 numbers.
EXP_LIMIT_F32 = 87.0
_MAGIC = 12582912.0  # 1.5 * 2^23: adding it rounds to an integer in the low bits
_MAGIC_BITS = int(np.array([_MAGIC], np.float32).view(np.int32)[0])
_SQRT_HALF_BITS = int(np.array([math.sqrt(0.5)], np.float32).view(np.int32)[0])
_LN2_HI = 0.693359375  # ln 2 split so that k * _LN2_HI is exact in float32 for |k| < 2^7
_LN2_LO = -2.12194440e-4
_EXP_COEFFS = tuple(1.0 / math.factorial(k) for k in range(8))  # |r| <= ln2/2: 5e-9
_LOG_COEFFS = tuple(2.0 / (2 * k + 1) for k in range(5))  # |s| <= 0.172: s^11 term 2e-9


def erfcx_fit_f32() -> np.ndarray:
    """Monomial coefficients (lowest first) of erfcx(y) as a polynomial in s = (t - t_lo)
    / (1 - t_lo) * 2 - 1, t = 1 / (1 + y / 2), y in [0, ERFC_Y_MAX_F32], interpolated at
    Chebyshev nodes of s (relative error 2e-8)."""
    k = np.arange(_ERFCX_DEGREE + 1)
    s = np.cos(np.pi * (k + 0.5) / (_ERFCX_DEGREE + 1))
    t = _T_LO + 0.5 * (s + 1.0) * (1.0 - _T_LO)
    y = (1.0 / t - 1.0) / 0.5
    values = np.array([math.exp(v * v) * math.erfc(v) for v in y])
    return np.polynomial.chebyshev.cheb2poly(
        np.polynomial.chebyshev.chebfit(s, values, _ERFCX_DEGREE))


_ERFCX = tuple(float(c) for c in erfcx_fit_f32())


def const_f32(value: float) -> ir.Constant:
    """A vector of ``value`` (rounded to float32)."""
    return ir.Constant(VEC_F32, [float(np.float32(value))] * WIDTH_F32)


def iconst_i32(value: int) -> ir.Constant:
    """An int32 vector of ``value``."""
    return ir.Constant(IVEC_I32, [int(value)] * WIDTH_F32)


def splat_f32(b: ir.IRBuilder, scalar: ir.Value) -> ir.Value:
    """A vector of the double ``scalar`` rounded to float32."""
    one = b.insert_element(ir.Constant(VEC_F32, ir.Undefined), b.fptrunc(scalar, F32),
                           ir.Constant(I32, 0))
    return b.shuffle_vector(one, ir.Constant(VEC_F32, ir.Undefined),
                            ir.Constant(ir.VectorType(I32, WIDTH_F32), [0] * WIDTH_F32))


def join(b: ir.IRBuilder, parts: list[ir.Value]) -> ir.Value:
    """The 8-lane vector of ``parts`` (one 8-lane vector, or two 4-lane ones, lowest
    first; any element type)."""
    if len(parts) == 1:
        return parts[0]
    low, high = parts
    return b.shuffle_vector(low, high, ir.Constant(ir.VectorType(I32, 2 * 4), list(range(8))))


def split(b: ir.IRBuilder, x: ir.Value, width: int) -> tuple[ir.Value, ...]:
    """The ``width``-lane parts of an 8-lane vector, lowest first (x itself for 8)."""
    if width == WIDTH_F32:
        return (x,)
    undefined = ir.Constant(x.type, ir.Undefined)
    return tuple(b.shuffle_vector(x, undefined, ir.Constant(ir.VectorType(I32, width),
                                                            list(range(h * width,
                                                                       (h + 1) * width))))
                 for h in range(WIDTH_F32 // width))


def horner_f32(b: ir.IRBuilder, xs: list[ir.Value], coeffs: tuple[float, ...]
               ) -> list[ir.Value]:
    """sum coeffs[k] x^k by Horner's rule for each x, with fused multiply-adds where the
    target has them."""
    acc = [const_f32(coeffs[-1])] * len(xs)
    for c in reversed(coeffs[:-1]):
        acc = [intrinsic_call(b, "fmuladd", a, x, const_f32(c)) for a, x in zip(acc, xs)]
    return acc


def exp_f32(b: ir.IRBuilder, vs: list[ir.Value]) -> list[ir.Value]:
    """exp(v) for each v, clamped to [-EXP_LIMIT_F32, EXP_LIMIT_F32]: v = k ln2 + r, e^r
    by Taylor to degree 7, 2^k in the exponent bits."""
    vs = [vmin(b, vmax(b, x, const_f32(-EXP_LIMIT_F32)), const_f32(EXP_LIMIT_F32))
          for x in vs]
    ts = [b.fadd(b.fmul(x, const_f32(1.0 / math.log(2.0))), const_f32(_MAGIC)) for x in vs]
    ks = [b.fsub(t, const_f32(_MAGIC)) for t in ts]
    rs = [b.fsub(b.fsub(x, b.fmul(k, const_f32(_LN2_HI))), b.fmul(k, const_f32(_LN2_LO)))
          for x, k in zip(vs, ks)]
    scales = [b.bitcast(b.shl(b.add(b.sub(b.bitcast(t, IVEC_I32), iconst_i32(_MAGIC_BITS)),
                                    iconst_i32(127)), iconst_i32(23)), VEC_F32) for t in ts]
    return [b.fmul(p, scale) for p, scale in zip(horner_f32(b, rs, _EXP_COEFFS), scales)]


def log_f32(b: ir.IRBuilder, ys: list[ir.Value]) -> list[ir.Value]:
    """log(y) for each positive normal y: y = 2^e m, m in [sqrt(1/2), sqrt 2), log m =
    2 atanh((m - 1) / (m + 1)) by its series to s^9."""
    shifted = [b.sub(b.bitcast(y, IVEC_I32), iconst_i32(_SQRT_HALF_BITS)) for y in ys]
    es = [b.sitofp(b.ashr(x, iconst_i32(23)), VEC_F32) for x in shifted]
    ms = [b.bitcast(b.add(b.and_(x, iconst_i32((1 << 23) - 1)), iconst_i32(_SQRT_HALF_BITS)),
                    VEC_F32) for x in shifted]
    ss = [b.fdiv(b.fsub(m, const_f32(1.0)), b.fadd(m, const_f32(1.0))) for m in ms]
    ps = horner_f32(b, [b.fmul(s, s) for s in ss], _LOG_COEFFS)
    return [b.fadd(b.fmul(e, const_f32(math.log(2.0))), b.fmul(s, p))
            for e, s, p in zip(es, ss, ps)]


def erfc_f32(b: ir.IRBuilder, xs: list[ir.Value]) -> list[ir.Value]:
    """erfc(x) = exp(-y^2) erfcx(y) for y = min(|x|, ERFC_Y_MAX_F32), 2 - that for x < 0."""
    ys = [vmin(b, intrinsic_call(b, "fabs", x), const_f32(ERFC_Y_MAX_F32)) for x in xs]
    ts = [b.fdiv(const_f32(1.0), b.fadd(const_f32(1.0), b.fmul(y, const_f32(0.5))))
          for y in ys]
    ss = [b.fsub(b.fmul(b.fsub(t, const_f32(_T_LO)), const_f32(2.0 / (1.0 - _T_LO))),
                 const_f32(1.0)) for t in ts]
    gaussians = exp_f32(b, [b.fsub(const_f32(0.0), b.fmul(y, y)) for y in ys])
    upper = [b.fmul(g, p) for g, p in zip(gaussians, horner_f32(b, ss, _ERFCX))]
    return [b.select(b.fcmp_ordered("<", x, const_f32(0.0)), b.fsub(const_f32(2.0), u), u)
            for x, u in zip(xs, upper)]
