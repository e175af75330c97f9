"""LLVM IR for the lane intrinsics (:mod:`drake_tracker.core.simd.lanes`): <8 x double>
vectors, and the few operations on them that the rasteriser needs.

Nothing here is called at run time: these functions emit IR into the intrinsics' code.
The pixel likelihood's exp, log and erfc are single precision
(:mod:`drake_tracker.core.simd.ir_f32`).
"""

from __future__ import annotations

from collections.abc import Callable

from llvmlite import ir
from numba.core import cgutils

#: Doubles per LLVM vector: all 8 lanes of a batch, one AVX-512 register. Where the
#: target's registers are narrower, LLVM splits each operation (two AVX2 ones, four
#: NEON ones): on a Zen 5 core, with the code built for its AVX-512 and for AVX2 alone,
#: 8 against 4 doubles per vector gave 1.14-1.21x and 1.00-1.06x image updates/s.
#: The arithmetic is per lane, so the width changes no result.
WIDTH = 8
F64 = ir.DoubleType()
I64 = ir.IntType(64)
VEC = ir.VectorType(F64, WIDTH)


def const(value: float) -> ir.Constant:
    """A vector of ``value``."""
    return ir.Constant(VEC, [float(value)] * WIDTH)


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


def intrinsic_call(b: ir.IRBuilder, name: str, *args: ir.Value) -> ir.Value:
    """LLVM's vector intrinsic ``llvm.<name>`` on ``args`` (vectors of one type, double
    or float), e.g. "fabs", "fmuladd"."""
    kind = args[0].type
    suffix = f"v{kind.count}f{64 if kind.element == F64 else 32}"
    fn = cgutils.get_or_insert_function(
        b.module, ir.FunctionType(kind, [kind] * len(args)), f"llvm.{name}.{suffix}")
    return b.call(fn, list(args))


def vmin(b: ir.IRBuilder, x: ir.Value, y: ir.Value) -> ir.Value:
    """Lane-wise x < y ? x : y, for vectors of any element type (one instruction on x86;
    no NaN reaches it here)."""
    return b.select(b.fcmp_ordered("<", x, y), x, y)


def vmax(b: ir.IRBuilder, x: ir.Value, y: ir.Value) -> ir.Value:
    """Lane-wise x > y ? x : y, for vectors of any element type (one instruction on x86;
    no NaN reaches it here)."""
    return b.select(b.fcmp_ordered(">", x, y), x, y)


def zmax(b: ir.IRBuilder, x: ir.Value, y: ir.Value) -> ir.Value:
    """max(x, y) of values that are not NaN (one instruction where the target has it;
    unlike a compare-and-select of a loaded value, never turned into a masked store)."""
    fn = cgutils.get_or_insert_function(
        b.module, ir.FunctionType(VEC, [VEC, VEC]), f"llvm.maxnum.v{WIDTH}f64")
    return b.call(fn, [x, y], fastmath=("nnan",))


def vabs(b: ir.IRBuilder, x: ir.Value) -> ir.Value:
    """Lane-wise |x|."""
    return intrinsic_call(b, "fabs", x)


def vceil(b: ir.IRBuilder, x: ir.Value) -> ir.Value:
    """Lane-wise ceil."""
    return intrinsic_call(b, "ceil", x)


def vfloor(b: ir.IRBuilder, x: ir.Value) -> ir.Value:
    """Lane-wise floor."""
    return intrinsic_call(b, "floor", x)


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
