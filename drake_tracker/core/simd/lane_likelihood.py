"""The pixel likelihood for 8 particles at once (see :mod:`drake_tracker.core.simd.lanes`).

:func:`lane_pixel_score` scores one observed pixel against the depths that the
:data:`~drake_tracker.core.simd.lanes.LANES` particles of a batch rendered there: the term of
:mod:`drake_tracker.core.likelihood.pixel_model`, ``log(p(z | d) / p_occ(z | inf))``, with the
pixel's constants broadcast to all lanes, so no lane reads anything of its own but its depth
(:attr:`~drake_tracker.core.likelihood.pixel_model.PreparedObservation.pixel_table`, built once per
image, holds them).

The mixture is evaluated in single precision, all LANES lanes in one vector, with exp,
log and erfc from :mod:`drake_tracker.core.simd.ir_f32`: half the instructions of double
lanes (1.2x an image update on an AVX2 machine). The difference z - d of the observed
and rendered depths is formed in double before it is rounded, and each pixel's terms
are summed in double, so each term is within :data:`TERM_ATOL_F32` + :data:`TERM_RTOL_F32`
of its size of the double-precision term (tested against the direct transcription),
and a score of P pixels within P times that (a few hundred ulps of float32 in all; the
errors' signs vary, so in practice far less: at most 2e-4 nats at 80x60 and 7e-4 at
160x120 on scores of thousands, measured).
"""

from __future__ import annotations

import math

from llvmlite import ir
from numba import types
from numba.extending import intrinsic

from drake_tracker.core.likelihood.pixel_model import (
    PIXEL_COLUMNS,
    TABLE_GAUSS,
    TABLE_INV_SIGMA,
    TABLE_LAM_SIGMA2,
    TABLE_LOG_P_OCC_INF,
    TABLE_OCC,
    TABLE_Z,
)
from drake_tracker.core.simd import ir_f32 as f
from drake_tracker.core.simd import ir_f64 as v
from drake_tracker.core.simd.ir_f64 import I64, WIDTH
from drake_tracker.core.simd.lanes import LANES

#: Pixels scored per call of :func:`lane_pixel_scores`: their instruction chains are
#: interleaved, so that the CPU overlaps them.
PIXELS_PER_CALL = 2
#: Each pixel's term agrees with the double-precision one within TERM_ATOL_F32 (nats)
#: plus TERM_RTOL_F32 of its size: the float32 rounding of a dozen operations.
TERM_ATOL_F32 = 2e-6
TERM_RTOL_F32 = 2e-6
#: A score's stated tolerance per pixel where the particle's robot is drawn: a term's
#: for terms of up to 4 nats (most are; the float32 errors' signs vary, so a sum of
#: many stays far below this times the pixels).
SCORE_ATOL_PER_PIXEL = TERM_ATOL_F32 + 4.0 * TERM_RTOL_F32
_F32_HALF = ir.VectorType(ir.FloatType(), WIDTH)


def _score_codegen(truncated: bool):
    def codegen(context, b, signature, args):
        zb, offsets, pixels, k, acc, table, uniform, lam, occlusion, truncation = args
        z_d, off_d, pix_d, a_d, t_d = (
            context.make_array(signature.args[i])(context, b, args[i]).data
            for i in (0, 1, 2, 4, 5))
        zero = v.const(0.0)
        halves = LANES // WIDTH
        ptrs, hits, dzs, ds, consts = [], [], [], [], []
        for j in range(PIXELS_PER_CALL):
            entry = v.add_offset(b, k, j)
            zoff = b.load(b.gep(off_d, [entry]))
            base = b.mul(b.load(b.gep(pix_d, [entry])), ir.Constant(I64, PIXEL_COLUMNS))
            column = [b.load(b.gep(t_d, [v.add_offset(b, base, c)])) for c in range(6)]
            z = v.splat(b, column[TABLE_Z])
            pixel_hits, pixel_dz, pixel_d = [], [], []
            for h in range(halves):
                ptrs.append(v.pointer(b, z_d, v.add_offset(b, zoff, h * WIDTH)))
                iz = b.load(ptrs[-1], align=8)
                pixel_hits.append(b.fcmp_ordered(">", iz, zero))
                # the rendered image's float32 depth, as the plain likelihood reads it;
                # z - d in double (both exact there), then rounded to float32
                d32 = b.fptrunc(b.fdiv(v.const(1.0), iz), _F32_HALF)
                pixel_d.append(d32)
                pixel_dz.append(b.fptrunc(b.fsub(z, b.fpext(d32, v.VEC)), _F32_HALF))
            hits.append(f.join(b, pixel_hits))
            dzs.append(f.join(b, pixel_dz))
            ds.append(f.join(b, pixel_d))
            consts.append([f.splat_f32(b, value) for value in column])
        # the mixture in float32, all LANES lanes in one vector
        u, o = f.splat_f32(b, uniform), f.splat_f32(b, occlusion)
        rrs = [b.fmul(dz, c[TABLE_INV_SIGMA]) for dz, c in zip(dzs, consts)]
        gauss = f.exp_f32(b, [b.fmul(f.const_f32(-0.5), b.fmul(rr, rr)) for rr in rrs])
        xs = [b.fmul(b.fsub(dz, c[TABLE_LAM_SIGMA2]),
                     b.fmul(c[TABLE_INV_SIGMA], f.const_f32(math.sqrt(0.5))))
              for dz, c in zip(dzs, consts)]
        occluded = [b.fmul(c[TABLE_OCC], b.fmul(f.const_f32(0.5), e))
                    for c, e in zip(consts, f.erfc_f32(b, xs))]
        if truncated:
            minus_lam = b.fsub(f.const_f32(0.0), f.splat_f32(b, lam))
            decay = f.exp_f32(b, [b.fmul(minus_lam, d) for d in ds])
            occluded = [b.fdiv(x, b.fsub(f.const_f32(1.0),
                                         b.fmul(f.splat_f32(b, truncation), e)))
                        for x, e in zip(occluded, decay)]
        mixes = [b.fadd(b.fmul(b.fsub(f.const_f32(1.0), o),
                               b.fadd(u, b.fmul(c[TABLE_GAUSS], g))),
                        b.fmul(o, b.fadd(u, x)))
                 for c, g, x in zip(consts, gauss, occluded)]
        logs = f.log_f32(b, [b.select(hit, mix, f.const_f32(1.0))
                             for hit, mix in zip(hits, mixes)])
        # each pixel's terms back to double halves, summed in double
        sums = [zero] * halves
        for lg, c, hit in zip(logs, consts, hits):
            term = b.select(hit, b.fsub(lg, c[TABLE_LOG_P_OCC_INF]), f.const_f32(0.0))
            for h, part in enumerate(f.split(b, term, WIDTH)):
                sums[h] = b.fadd(sums[h], b.fpext(part, v.VEC))
        for ptr in ptrs:
            b.store(zero, ptr, align=8)
        for h, total in enumerate(sums):
            v.store(b, b.fadd(v.load(b, a_d, h * WIDTH), total), a_d, h * WIDTH)
        return context.get_dummy_value()

    return codegen


@intrinsic
def lane_pixel_scores(typingctx: object, zb: types.Type, offsets: types.Type,
                      pixels: types.Type, k: types.Type, acc: types.Type,
                      table: types.Type, uniform: types.Type, lam: types.Type,
                      occlusion: types.Type, truncation: types.Type) -> tuple:
    """For entries k, ..., k + PIXELS_PER_CALL - 1 of ``offsets``/``pixels`` (a pixel's
    offset in ``zb``, and its row in ``table``, a
    :attr:`~drake_tracker.core.likelihood.pixel_model.PreparedObservation.pixel_table`): acc[l] +=
    log(p(z | d_l) / p_occ(z | inf)) for each lane l whose inverse depth 1/d_l there is
    > 0, with the independent occluder depth; those pixels of ``zb`` are set to 0."""
    sig = types.void(zb, offsets, pixels, k, acc, table, uniform, lam, occlusion, truncation)
    return sig, _score_codegen(truncated=False)


@intrinsic
def lane_pixel_scores_truncated(typingctx: object, zb: types.Type, offsets: types.Type,
                                pixels: types.Type, k: types.Type, acc: types.Type,
                                table: types.Type, uniform: types.Type, lam: types.Type,
                                occlusion: types.Type, truncation: types.Type) -> tuple:
    """:func:`lane_pixel_scores` with the occluder depth truncated to [0, d] (the
    paper's), whose normaliser 1 / (1 - truncation e^{-lam d}) the occlusion term gets."""
    sig = types.void(zb, offsets, pixels, k, acc, table, uniform, lam, occlusion, truncation)
    return sig, _score_codegen(truncated=True)


@intrinsic
def lane_any(typingctx: object, zb: types.Type, offset: types.Type) -> tuple:
    """Whether any of the LANES inverse depths at ``zb[offset:]`` is > 0."""
    sig = types.boolean(zb, offset)

    def codegen(context, b, signature, args):
        z_d = context.make_array(signature.args[0])(context, b, args[0]).data
        hits = [b.fcmp_ordered(">", v.load(b, z_d, v.add_offset(b, args[1], h * WIDTH)),
                               v.const(0.0)) for h in range(LANES // WIDTH)]
        return v.any_true(b, hits)

    return sig, codegen
