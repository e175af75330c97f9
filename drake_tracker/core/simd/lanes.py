"""SIMD across particles: numba intrinsics that work on 8 particles ("lanes") at once.

The particles of one CPF block are nearly the same configuration, so one pass over the
triangles and pixels can serve 8 of them: every per-particle quantity (a vertex's pixel
coordinates, a triangle's edge coefficients, a pixel's depth) is stored as 8 contiguous
float64 lanes, and the intrinsics below act on all of them with vector instructions.
Numba's own loops do not vectorise such short lane loops (LLVM cannot rule out that the
arrays alias, so it unrolls them into scalar code); these emit the vector LLVM IR
(:mod:`drake_tracker.core.simd.ir_f64`) directly, which any LLVM target lowers to its SIMD.

The arithmetic is that of the scalar rasteriser (:mod:`drake_tracker.core.render.rasterize`:
projection, culling, the box path's setup and edge tests; no fused multiply-add) and of
the plain likelihood, so each lane's image is the scalar rasteriser's image.

Arrays are passed flattened: per-vertex (V * LANES), per-body poses (num_bodies * 12 *
LANES: the 3x4 rows of each camera-frame pose), the z-buffer (H * W * LANES inverse
depths, 0 where nothing is drawn), a triangle's coefficients (COEFF_ROWS * LANES).
"""

from __future__ import annotations

import math

from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic

from drake_tracker.core.simd import ir_f64 as v
from drake_tracker.core.simd.ir_f64 import F64, I64, WIDTH

#: Particles processed together.
LANES = 8
_HALVES = LANES // WIDTH

#: Rows of a triangle's coefficients (each LANES wide): edge k holds where
#: A_k c + (B_k r + G_k) >= 0; 1/z = AI c + (BI r + KI); the lane's box [CLO, CHI] x
#: [RLO, RHI]; its inverse depth range [IZLO, IZHI] (-inf, inf: no test needed).
(A0, B0, G0, A1, B1, G1, A2, B2, G2, AI, BI, KI, CLO, CHI, RLO, RHI, IZLO, IZHI) = range(18)
COEFF_ROWS = 18
#: The rasteriser's slack on the edge functions (see rasterize._raster).
_EPS = -1e-9

_TRUE = ir.Constant(ir.VectorType(ir.IntType(1), WIDTH), [1] * WIDTH)
_FALSE = ir.Constant(ir.VectorType(ir.IntType(1), WIDTH), [0] * WIDTH)


def _data(context, b, array_type, value):
    return context.make_array(array_type)(context, b, value).data


def _row(k: int, h: int) -> int:
    return k * LANES + h * WIDTH


@intrinsic
def lane_project(typingctx: object, U: types.Type, Vv: types.Type, IZ: types.Type,
                 Z: types.Type, i: types.Type, poses: types.Type, body: types.Type,
                 px: types.Type, py: types.Type, pz: types.Type, fx: types.Type,
                 fy: types.Type, cx: types.Type, cy: types.Type) -> tuple:
    """Vertex i (body-frame px, py, pz of body ``body``) projected for each lane:
    U/Vv = fx x / z + cx, fy y / z + cy, IZ = 1/z and Z = z at row i."""
    sig = types.void(U, Vv, IZ, Z, i, poses, body, px, py, pz, fx, fy, cx, cy)

    def codegen(context, b, signature, args):
        u_d, v_d, iz_d, z_d, p_d = (_data(context, b, signature.args[k], args[k])
                                    for k in (0, 1, 2, 3, 5))
        point = [v.splat(b, args[k]) for k in (7, 8, 9)]
        fx, fy, cx, cy = (v.splat(b, args[k]) for k in (10, 11, 12, 13))
        base = b.mul(args[6], ir.Constant(I64, 12 * LANES))
        out = b.mul(args[4], ir.Constant(I64, LANES))
        for h in range(_HALVES):
            xyz = []
            for row in range(3):
                m = [v.load(b, p_d, v.add_offset(b, base, _row(4 * row + col, h)))
                     for col in range(4)]
                acc = b.fadd(b.fmul(m[0], point[0]), b.fmul(m[1], point[1]))
                xyz.append(b.fadd(b.fadd(acc, b.fmul(m[2], point[2])), m[3]))
            iz = b.fdiv(v.const(1.0), xyz[2])
            offset = v.add_offset(b, out, h * WIDTH)
            v.store(b, b.fadd(b.fmul(b.fmul(fx, xyz[0]), iz), cx), u_d, offset)
            v.store(b, b.fadd(b.fmul(b.fmul(fy, xyz[1]), iz), cy), v_d, offset)
            v.store(b, iz, iz_d, offset)
            v.store(b, xyz[2], z_d, offset)
        return context.get_dummy_value()

    return sig, codegen


def _setup(b, co_d, h, uu, vv, zz, area, ok, box, iz_lo, iz_hi):
    """Stores half h's coefficient rows (the scalar rasteriser's setup, lanes not ``ok``
    set to draw nothing)."""
    zero, inf = v.const(0.0), v.const(math.inf)
    inv = b.fdiv(v.const(1.0), area)
    edge = []
    for i, j in ((1, 2), (2, 0), (0, 1)):  # edge k: vertices (k+1, k+2)
        a = b.fmul(b.fsub(vv[i], vv[j]), inv)
        bb = b.fmul(b.fsub(uu[j], uu[i]), inv)
        k = b.fmul(b.fsub(b.fmul(uu[i], vv[j]), b.fmul(uu[j], vv[i])), inv)
        edge.append((a, bb, k))

    def weighted(col):
        return b.fadd(b.fadd(b.fmul(edge[0][col], zz[0]), b.fmul(edge[1][col], zz[1])),
                      b.fmul(edge[2][col], zz[2]))

    check = b.or_(b.fcmp_ordered(">", v.vmax(b, zz[0], v.vmax(b, zz[1], zz[2])), iz_hi),
                  b.fcmp_ordered("<", v.vmin(b, zz[0], v.vmin(b, zz[1], zz[2])), iz_lo))
    c0, c1, r0, r1 = box
    rows = {AI: weighted(0), BI: weighted(1), KI: weighted(2), CLO: c0, CHI: c1, RLO: r0,
            RHI: r1, IZLO: b.select(check, iz_lo, v.const(-math.inf)),
            IZHI: b.select(check, iz_hi, inf)}
    for k, (a, bb, kk) in enumerate(edge):
        rows[(A0, A1, A2)[k]] = a
        rows[(B0, B1, B2)[k]] = bb
        rows[(G0, G1, G2)[k]] = b.fsub(kk, v.const(_EPS))
    # lanes that draw nothing: an empty box and edges that reject every pixel
    empty = {CLO: inf, CHI: v.const(-math.inf), RLO: v.const(1.0), RHI: zero,
             G0: v.const(-1.0), IZLO: v.const(-math.inf), IZHI: inf}
    for k, value in rows.items():
        if k in empty:
            value = b.select(ok, value, empty[k])
        else:
            value = b.select(ok, value, zero)
        v.store(b, value, co_d, _row(k, h))


@intrinsic
def lane_triangle(typingctx: object, co: types.Type, box: types.Type, U: types.Type,
                  Vv: types.Type, IZ: types.Type, ia: types.Type, ib: types.Type,
                  ic: types.Type, planes: types.Type, t: types.Type, closed: types.Type,
                  origin: types.Type, fast: types.Type, w1: types.Type, h1: types.Type,
                  iz_lo: types.Type, iz_hi: types.Type) -> tuple:
    """Culls and sets up triangle t (vertex rows ia, ib, ic; ``planes`` (T, 4): n and
    offset, facing the camera where n . origin > offset, for a closed surface) for
    every lane where ``fast`` (LANES doubles) is nonzero: 1 with back-face culling (the
    part is in front of the near plane), 2 without (the part reaches it, this triangle
    does not), ``iz_lo``/``iz_hi`` the inverse depths of the far and
    (with the rasteriser's slack) the near plane. Returns the lanes that draw it as
    bits; writes their coefficients into ``co`` and the union of their boxes (r0, r1,
    c0, c1) into ``box[:4]``. ``origin``: (3, LANES) the camera's origin in the body
    frame."""
    sig = types.int64(co, box, U, Vv, IZ, ia, ib, ic, planes, t, closed, origin, fast, w1,
                      h1, iz_lo, iz_hi)

    def codegen(context, b, signature, args):
        co_d, box_d, u_d, v_d, iz_d = (_data(context, b, signature.args[k], args[k])
                                       for k in range(5))
        n_d, o_d, fast_d = (_data(context, b, signature.args[k], args[k]) for k in (8, 11, 12))
        w1, h1, iz_lo, iz_hi = (v.splat(b, args[k]) for k in (13, 14, 15, 16))
        t4 = b.mul(args[9], ir.Constant(I64, 4))
        nrm = [v.splat(b, b.load(b.gep(n_d, [v.add_offset(b, t4, k)]))) for k in range(4)]
        open_surface = b.select(b.icmp_unsigned("!=", args[10],
                                                ir.Constant(args[10].type, 0)),
                                _FALSE, _TRUE)
        rows = [b.mul(args[k], ir.Constant(I64, LANES)) for k in (5, 6, 7)]
        zero = v.const(0.0)
        # Back faces first: a triangle that faces away in every lane (about half of a
        # closed part's) skips its boxes and setup.
        live = []
        for h in range(_HALVES):
            o = [v.load(b, o_d, _row(k, h)) for k in range(3)]
            facing = b.fadd(b.fadd(b.fmul(nrm[0], o[0]), b.fmul(nrm[1], o[1])),
                            b.fmul(nrm[2], o[2]))
            state = v.load(b, fast_d, h * WIDTH)
            front = b.or_(b.or_(b.fcmp_ordered(">", facing, nrm[3]), open_surface),
                          b.fcmp_ordered("==", state, v.const(2.0)))
            live.append(b.and_(front, b.fcmp_ordered("!=", state, zero)))
        result = cgutils.alloca_once_value(b, ir.Constant(I64, 0))
        with b.if_then(v.any_true(b, live)):
            b.store(_boxes_and_setup(b, co_d, box_d, (u_d, v_d, iz_d), rows, live, w1, h1,
                                     iz_lo, iz_hi), result)
        return b.load(result)

    return sig, codegen


def _boxes_and_setup(b, co_d, box_d, vertex_data, rows, live, w1, h1, iz_lo, iz_hi):
    """:func:`lane_triangle`'s work for a triangle that faces the camera in the lanes
    ``live`` (a mask per half): each lane's pixel box, and the setup of those lanes whose
    box holds a pixel centre. Returns the lanes that draw it as bits (an i64 value)."""
    zero = v.const(0.0)
    u_d, v_d, iz_d = vertex_data
    masks, halves = [], []
    for h in range(_HALVES):
        uu, vv, zz = ([v.load(b, d, v.add_offset(b, r, h * WIDTH)) for r in rows]
                      for d in (u_d, v_d, iz_d))
        c0 = v.vmax(b, zero, v.vceil(b, v.vmin(b, uu[0], v.vmin(b, uu[1], uu[2]))))
        c1 = v.vmin(b, w1, v.vfloor(b, v.vmax(b, uu[0], v.vmax(b, uu[1], uu[2]))))
        r0 = v.vmax(b, zero, v.vceil(b, v.vmin(b, vv[0], v.vmin(b, vv[1], vv[2]))))
        r1 = v.vmin(b, h1, v.vfloor(b, v.vmax(b, vv[0], v.vmax(b, vv[1], vv[2]))))
        masks.append(b.and_(live[h], b.and_(b.fcmp_ordered("<=", c0, c1),
                                            b.fcmp_ordered("<=", r0, r1))))
        halves.append((uu, vv, zz, (c0, c1, r0, r1)))
    result = cgutils.alloca_once_value(b, ir.Constant(I64, 0))
    with b.if_then(v.any_true(b, masks)):
        final = []
        bounds = [None] * 4
        for h, (uu, vv, zz, box) in enumerate(halves):
            area = b.fsub(b.fmul(b.fsub(uu[1], uu[0]), b.fsub(vv[2], vv[0])),
                          b.fmul(b.fsub(uu[2], uu[0]), b.fsub(vv[1], vv[0])))
            ok = b.and_(masks[h], b.fcmp_ordered(">=", v.vabs(b, area), v.const(1e-12)))
            final.append(ok)
            _setup(b, co_d, h, uu, vv, zz, area, ok, box, iz_lo, iz_hi)
            c0, c1, r0, r1 = box
            for k, (value, pick, none) in enumerate(
                    ((r0, v.vmin, math.inf), (r1, v.vmax, -math.inf),
                     (c0, v.vmin, math.inf), (c1, v.vmax, -math.inf))):
                value = b.select(ok, value, v.const(none))
                bounds[k] = value if bounds[k] is None else pick(b, bounds[k], value)
        with b.if_then(v.any_true(b, final)):
            for k, pick in enumerate((v.vmin, v.vmax, v.vmin, v.vmax)):
                b.store(b.fptosi(v.reduce(b, bounds[k], pick), I64),
                        b.gep(box_d, [ir.Constant(I64, k)]))
            b.store(v.bits(b, final), result)
    return b.load(result)


def _scalar(b: ir.IRBuilder, fn, x: ir.Value) -> ir.Value:
    """``fn`` (a vector op) applied to the double x."""
    return b.extract_element(fn(b, v.splat(b, x)), ir.Constant(ir.IntType(32), 0))


def _run_bounds(b, c):
    """Per edge k of a half's coefficients ``c``, the bounds of its runs of columns:
    lo_s r + lo_t <= column (A_k > 0), column <= hi_s r + hi_t (A_k < 0)."""
    zero = v.const(0.0)
    bounds = []
    for a, bb, g in ((A0, B0, G0), (A1, B1, G1), (A2, B2, G2)):
        inv = b.fdiv(v.const(-1.0), c[a])
        slope, offset = b.fmul(c[bb], inv), b.fmul(c[g], inv)
        positive = b.fcmp_ordered(">", c[a], zero)
        negative = b.fcmp_ordered("<", c[a], zero)
        bounds.append((b.select(positive, slope, zero),
                       b.select(positive, offset, v.const(-math.inf)),
                       b.select(negative, slope, zero),
                       b.select(negative, offset, v.const(math.inf))))
    return bounds


def _run(b, halves, fr):
    """The union over the lanes reaching row fr of their runs of columns, widened by
    1e-6 px (so that no column an edge test accepts is left out): (first, last) as
    doubles, first > last when no lane reaches the row."""
    run_lo = run_hi = None
    for c, reached, bounds in halves:
        lo, hi = c[CLO], c[CHI]
        for lo_s, lo_t, hi_s, hi_t in bounds:
            lo = v.vmax(b, lo, b.fadd(b.fmul(lo_s, fr), lo_t))
            hi = v.vmin(b, hi, b.fadd(b.fmul(hi_s, fr), hi_t))
        lo = b.select(reached, lo, v.const(math.inf))
        hi = b.select(reached, hi, v.const(-math.inf))
        run_lo = lo if run_lo is None else v.vmin(b, run_lo, lo)
        run_hi = hi if run_hi is None else v.vmax(b, run_hi, hi)
    first = _scalar(b, lambda b, x: v.vceil(b, b.fsub(x, v.const(1e-6))),
                    v.reduce(b, run_lo, v.vmin))
    last = _scalar(b, lambda b, x: v.vfloor(b, b.fadd(x, v.const(1e-6))),
                   v.reduce(b, run_hi, v.vmax))
    return first, last


def _emit_rows(b, z_d, s_d, halves, width, r0, r1, box_lo, box_hi, runs, check_range):
    """The row and column loops of :func:`lane_raster` (``runs``, ``check_range``:
    whether to narrow rows to their runs, and to test the depth range). A pixel is
    inside where the least of its tests' margins (edge functions, distances to the
    box and depth bounds) is >= 0: one compare, the same outcome as testing each (the
    margins are exact in sign: no NaN reaches them, and fl(a - b) has the sign of a - b)."""
    zero = v.const(0.0)
    bounds = [_run_bounds(b, c) for c in halves] if runs else [None] * len(halves)
    with cgutils.for_range(b, b.add(r1, ir.Constant(I64, 1)), start=r0) as row:
        fr = v.splat(b, b.sitofp(row.index, F64))
        per_half = []
        for c in halves:
            reached = b.and_(b.fcmp_ordered(">=", fr, c[RLO]), b.fcmp_ordered("<=", fr, c[RHI]))
            hk = [b.fadd(b.fmul(c[bk], fr), c[gk]) for bk, gk in ((B0, G0), (B1, G1),
                                                                  (B2, G2))]
            # a lane whose triangle does not reach this row fails its first edge
            hk[0] = b.select(reached, hk[0], v.const(-math.inf))
            per_half.append((c, reached, hk, b.fadd(b.fmul(c[BI], fr), c[KI])))
        lo_f, hi_f = box_lo, box_hi
        if runs:
            lo, hi = _run(b, [(c, ok, bd) for (c, ok, _, _), bd in zip(per_half, bounds)], fr)
            lo_f = _scalar(b, lambda b, x: v.vmax(b, x, v.splat(b, box_lo)), lo)
            hi_f = _scalar(b, lambda b, x: v.vmin(b, x, v.splat(b, box_hi)), hi)
        with b.if_then(b.fcmp_ordered("<=", lo_f, hi_f)):
            lo_i, hi_i = b.fptosi(lo_f, I64), b.fptosi(hi_f, I64)
            for col, keep, new in ((0, "<", lo_i), (1, ">", hi_i)):
                at = b.gep(s_d, [b.add(b.mul(row.index, ir.Constant(I64, 2)),
                                       ir.Constant(I64, col))])
                old = b.load(at)
                b.store(b.select(b.icmp_signed(keep, new, old), new, old), at)
            row_base = b.mul(row.index, width)
            with cgutils.for_range(b, b.add(hi_i, ir.Constant(I64, 1)), start=lo_i) as column:
                fc = v.splat(b, b.sitofp(column.index, F64))
                offset = b.mul(b.add(row_base, column.index), ir.Constant(I64, LANES))
                for h, (c, _, hk, ei) in enumerate(per_half):
                    margin = v.vmin(b, b.fsub(fc, c[CLO]), b.fsub(c[CHI], fc))
                    for a, hh in zip((A0, A1, A2), hk):
                        margin = v.vmin(b, margin, b.fadd(b.fmul(c[a], fc), hh))
                    iz = b.fadd(b.fmul(c[AI], fc), ei)
                    if check_range:
                        margin = v.vmin(b, margin, v.vmin(b, b.fsub(c[IZHI], iz),
                                                          b.fsub(iz, c[IZLO])))
                    inside = b.fcmp_ordered(">=", margin, zero)
                    at = v.add_offset(b, offset, h * WIDTH)
                    v.store(b, v.zmax(b, v.load(b, z_d, at), b.select(inside, iz, zero)),
                            z_d, at)


@intrinsic
def lane_raster(typingctx: object, zb: types.Type, width: types.Type, co: types.Type,
                r0: types.Type, r1: types.Type, c0: types.Type, c1: types.Type,
                runs: types.Type, span: types.Type) -> tuple:
    """Rasterises the triangle whose coefficients are ``co`` into ``zb`` over rows
    [r0, r1] and columns [c0, c1] (the union of the lanes' boxes), each row narrowed,
    when ``runs`` holds, to the union of the lanes' runs of columns there (the edge
    tests decide; the runs only skip columns no lane can draw). ``span`` (H, 2) grows
    to the columns visited in each row."""
    sig = types.void(zb, width, co, r0, r1, c0, c1, runs, span)

    def codegen(context, b, signature, args):
        z_d, co_d, s_d = (_data(context, b, signature.args[k], args[k]) for k in (0, 2, 8))
        halves = [{k: v.load(b, co_d, _row(k, h)) for k in range(COEFF_ROWS)}
                  for h in range(_HALVES)]
        use_runs = b.icmp_unsigned("!=", args[7], ir.Constant(args[7].type, 0))
        check_range = v.any_true(b, [b.fcmp_ordered("<", c[IZHI], v.const(math.inf))
                                     for c in halves])
        box_lo, box_hi = b.sitofp(args[5], F64), b.sitofp(args[6], F64)
        emit = (b, z_d, s_d, halves, args[1], args[3], args[4], box_lo, box_hi)
        with b.if_else(use_runs) as (with_runs, whole_box):
            for runs, block in ((True, with_runs), (False, whole_box)):
                with block:
                    with b.if_else(check_range) as (checked, unchecked):
                        with checked:
                            _emit_rows(*emit, runs, True)
                        with unchecked:
                            _emit_rows(*emit, runs, False)
        return context.get_dummy_value()

    return sig, codegen
