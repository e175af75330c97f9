"""LLVM IR for the lane intrinsics (:mod:`drake_tracker.core.lanes`): <4 x double>
vectors, and exp, log and erfc built from multiplies, adds and bit operations.

Nothing here is called at run time: these functions emit IR into the intrinsics'
code. exp and log follow :mod:`drake_tracker.core.vector_math` (the same polynomials);
erfc is exp(-y^2) erfcx(y), erfcx a polynomial fitted here at import
(:func:`erfcx_fit`, relative error below 1e-13 on [0, ERFC_Y_MAX]).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from llvmlite import ir
from numba.core import cgutils

#: Doubles per LLVM vector: AVX2's register, or two NEON ones.
WIDTH = 4
F64 = ir.DoubleType()
I64 = ir.IntType(64)
VEC = ir.VectorType(F64, WIDTH)
IVEC = ir.VectorType(I64, WIDTH)

#: erfc(y) = exp(-y^2) erfcx(y), erfcx(y) for y in [0, ERFC_Y_MAX] a polynomial in
#: s = (t - t_lo) / (1 - t_lo) * 2 - 1, t = 1 / (1 + y / 2). erfc(9.5) is below 1e-40.
ERFC_Y_MAX = 9.5
_ERFCX_DEGREE = 17
_T_LO = 1.0 / (1.0 + 0.5 * ERFC_Y_MAX)


def erfcx_fit() -> np.ndarray:
    """Monomial coefficients (lowest first) of erfcx(y) as a polynomial in s (see the
    module's constants), interpolated at Chebyshev nodes of s."""
    k = np.arange(_ERFCX_DEGREE + 1)
    s = np.cos(np.pi * (k + 0.5) / (_ERFCX_DEGREE + 1))
    t = _T_LO + 0.5 * (s + 1.0) * (1.0 - _T_LO)
    y = (1.0 / t - 1.0) / 0.5
    values = np.array([math.exp(v * v) * math.erfc(v) for v in y])
    return np.polynomial.chebyshev.cheb2poly(
        np.polynomial.chebyshev.chebfit(s, values, _ERFCX_DEGREE))


_ERFCX = tuple(float(c) for c in erfcx_fit())
_EXP_COEFFS = tuple(1.0 / math.factorial(k) for k in range(12))
_LOG_COEFFS = tuple(2.0 / (2 * k + 1) for k in range(10))
_MAGIC = 6755399441055744.0  # 1.5 * 2^52: adding it rounds to an integer in the low bits
_MAGIC_BITS = int(np.array([_MAGIC]).view(np.int64)[0])
_SQRT_HALF_BITS = int(np.array([math.sqrt(0.5)]).view(np.int64)[0])
_LN2_HI = 6.93147180369123816490e-01  # ln 2 split so that k * _LN2_HI is exact
_LN2_LO = 1.90821492927058770002e-10


def const(value: float) -> ir.Constant:
    """A vector of ``value``."""
    return ir.Constant(VEC, [float(value)] * WIDTH)


def iconst(value: int) -> ir.Constant:
    """An int64 vector of ``value``."""
    return ir.Constant(IVEC, [int(value)] * WIDTH)


def splat(b: ir.IRBuilder, scalar: ir.Value) -> ir.Value:
    """A vector of the double ``scalar``."""
    one = b.insert_element(ir.Constant(VEC, ir.Undefined), scalar,
                           ir.Constant(ir.IntType(32), 0))
    return b.shuffle_vector(one, ir.Constant(VEC, ir.Undefined),
                            ir.Constant(ir.VectorType(ir.IntType(32), WIDTH), [0] * WIDTH))


def pointer(b: ir.IRBuilder, data: ir.Value, offset: ir.Value | int) -> ir.Value:
    """A vector pointer to ``data`` (double*) + ``offset`` doubles."""
    if isinstance(offset, int):
        offset = ir.Constant(I64, offset)
    return b.bitcast(b.gep(data, [offset]), VEC.as_pointer())


def load(b: ir.IRBuilder, data: ir.Value, offset: ir.Value | int) -> ir.Value:
    """The vector at ``data`` + ``offset`` doubles (unaligned)."""
    return b.load(pointer(b, data, offset), align=8)


def store(b: ir.IRBuilder, value: ir.Value, data: ir.Value, offset: ir.Value | int) -> None:
    """Stores a vector at ``data`` + ``offset`` doubles (unaligned)."""
    b.store(value, pointer(b, data, offset), align=8)


def add_offset(b: ir.IRBuilder, base: ir.Value, extra: int) -> ir.Value:
    """``base + extra`` for an int64 value."""
    return b.add(base, ir.Constant(I64, extra)) if extra else base


def _llvm(b: ir.IRBuilder, name: str, *args: ir.Value) -> ir.Value:
    fn = cgutils.get_or_insert_function(
        b.module, ir.FunctionType(VEC, [VEC] * len(args)), f"llvm.{name}.v{WIDTH}f64")
    return b.call(fn, list(args))


def vmin(b: ir.IRBuilder, x: ir.Value, y: ir.Value) -> ir.Value:
    """Lane-wise x < y ? x : y (one instruction on x86; no NaN reaches it here)."""
    return b.select(b.fcmp_ordered("<", x, y), x, y)


def vmax(b: ir.IRBuilder, x: ir.Value, y: ir.Value) -> ir.Value:
    """Lane-wise x > y ? x : y (one instruction on x86; no NaN reaches it here)."""
    return b.select(b.fcmp_ordered(">", x, y), x, y)


def test(b: ir.IRBuilder, op: str, x: ir.Value, y: ir.Value) -> ir.Value:
    """The lanes where ``x op y`` holds (ordered compare) as an int64 mask (all ones or
    zero): masks combined with ``and_`` stay in vector registers, where <4 x i1>
    masks are packed and unpacked on x86."""
    return b.sext(b.fcmp_ordered(op, x, y), IVEC)


def keep(b: ir.IRBuilder, x: ir.Value, mask: ir.Value) -> ir.Value:
    """x where ``mask`` (from :func:`test`) holds, +0.0 elsewhere."""
    return b.bitcast(b.and_(b.bitcast(x, IVEC), mask), VEC)


def zmax(b: ir.IRBuilder, x: ir.Value, y: ir.Value) -> ir.Value:
    """max(x, y) of values that are not NaN (one instruction where the target has it;
    unlike a compare-and-select of a loaded value, never turned into a masked store)."""
    fn = cgutils.get_or_insert_function(
        b.module, ir.FunctionType(VEC, [VEC, VEC]), f"llvm.maxnum.v{WIDTH}f64")
    return b.call(fn, [x, y], fastmath=("nnan",))


def vabs(b: ir.IRBuilder, x: ir.Value) -> ir.Value:
    """Lane-wise |x|."""
    return _llvm(b, "fabs", x)


def vceil(b: ir.IRBuilder, x: ir.Value) -> ir.Value:
    """Lane-wise ceil."""
    return _llvm(b, "ceil", x)


def vfloor(b: ir.IRBuilder, x: ir.Value) -> ir.Value:
    """Lane-wise floor."""
    return _llvm(b, "floor", x)


def reduce(b: ir.IRBuilder, x: ir.Value,
           combine: Callable[[ir.IRBuilder, ir.Value, ir.Value], ir.Value]) -> ir.Value:
    """``combine`` (vmin or vmax) over the lanes of ``x``, as a double."""
    index = ir.VectorType(ir.IntType(32), WIDTH)
    width = WIDTH
    while width > 1:
        width //= 2
        order = [(j + width) % WIDTH for j in range(WIDTH)]
        x = combine(b, x, b.shuffle_vector(x, ir.Constant(VEC, ir.Undefined),
                                           ir.Constant(index, order)))
    return b.extract_element(x, ir.Constant(ir.IntType(32), 0))


def horner(b: ir.IRBuilder, xs: list[ir.Value], coeffs: tuple[float, ...]) -> list[ir.Value]:
    """sum coeffs[k] x^k by Horner's rule, for each x, with fused multiply-adds where
    the target has them (``llvm.fmuladd``)."""
    acc = [const(coeffs[-1])] * len(xs)
    for c in reversed(coeffs[:-1]):
        acc = [_llvm(b, "fmuladd", a, x, const(c)) for a, x in zip(acc, xs)]
    return acc


def exp(b: ir.IRBuilder, vs: list[ir.Value]) -> list[ir.Value]:
    """exp(v) for each v, clamped to [-700, 700]: v = k ln2 + r, e^r by Taylor to degree
    11, 2^k in the exponent bits. (Lists of vectors: their instructions are interleaved,
    so that independent chains overlap in the CPU.)"""
    vs = [vmin(b, vmax(b, x, const(-700.0)), const(700.0)) for x in vs]
    ts = [b.fadd(b.fmul(x, const(1.0 / math.log(2.0))), const(_MAGIC)) for x in vs]
    ks = [b.fsub(t, const(_MAGIC)) for t in ts]
    rs = [b.fsub(b.fsub(x, b.fmul(k, const(_LN2_HI))), b.fmul(k, const(_LN2_LO)))
          for x, k in zip(vs, ks)]
    scales = [b.bitcast(b.shl(b.add(b.sub(b.bitcast(t, IVEC), iconst(_MAGIC_BITS)),
                                    iconst(1023)), iconst(52)), VEC) for t in ts]
    return [b.fmul(p, scale) for p, scale in zip(horner(b, rs, _EXP_COEFFS), scales)]


def log(b: ir.IRBuilder, ys: list[ir.Value]) -> list[ir.Value]:
    """log(y) for each positive normal y: y = 2^e m, m in [sqrt(1/2), sqrt 2), log m =
    2 atanh((m - 1) / (m + 1)) by its series to s^19."""
    shifted = [b.sub(b.bitcast(y, IVEC), iconst(_SQRT_HALF_BITS)) for y in ys]
    # the exponent e as a double, by the magic number (AVX2 has no int64 -> double)
    es = [b.fsub(b.bitcast(b.add(b.ashr(x, iconst(52)), iconst(_MAGIC_BITS)), VEC),
                 const(_MAGIC)) for x in shifted]
    ms = [b.bitcast(b.add(b.and_(x, iconst((1 << 52) - 1)), iconst(_SQRT_HALF_BITS)), VEC)
          for x in shifted]
    ss = [b.fdiv(b.fsub(m, const(1.0)), b.fadd(m, const(1.0))) for m in ms]
    ps = horner(b, [b.fmul(s, s) for s in ss], _LOG_COEFFS)
    return [b.fadd(b.fmul(e, const(math.log(2.0))), b.fmul(s, p))
            for e, s, p in zip(es, ss, ps)]


def erfc(b: ir.IRBuilder, xs: list[ir.Value]) -> list[ir.Value]:
    """erfc(x) = exp(-y^2) erfcx(y) for y = min(|x|, ERFC_Y_MAX), 2 - that for x < 0."""
    ys = [vmin(b, vabs(b, x), const(ERFC_Y_MAX)) for x in xs]
    ts = [b.fdiv(const(1.0), b.fadd(const(1.0), b.fmul(y, const(0.5)))) for y in ys]
    ss = [b.fsub(b.fmul(b.fsub(t, const(_T_LO)), const(2.0 / (1.0 - _T_LO))), const(1.0))
          for t in ts]
    gaussians = exp(b, [b.fsub(const(0.0), b.fmul(y, y)) for y in ys])
    upper = [b.fmul(g, p) for g, p in zip(gaussians, horner(b, ss, _ERFCX))]
    return [b.select(b.fcmp_ordered("<", x, const(0.0)), b.fsub(const(2.0), u), u)
            for x, u in zip(xs, upper)]


def any_true(b: ir.IRBuilder, masks: list[ir.Value]) -> ir.Value:
    """i1: whether any lane of any of the <WIDTH x i1> ``masks`` holds."""
    either = masks[0]
    for mask in masks[1:]:
        either = b.or_(either, mask)
    return b.icmp_unsigned("!=", b.bitcast(either, ir.IntType(WIDTH)),
                           ir.Constant(ir.IntType(WIDTH), 0))


def bits(b: ir.IRBuilder, masks: list[ir.Value]) -> ir.Value:
    """int64 with bit WIDTH*h + j set where lane j of ``masks[h]`` holds."""
    out = ir.Constant(I64, 0)
    for h, mask in enumerate(masks):
        part = b.zext(b.bitcast(mask, ir.IntType(WIDTH)), I64)
        out = b.or_(out, b.shl(part, ir.Constant(I64, WIDTH * h)) if h else part)
    return out
