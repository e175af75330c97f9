"""Forward kinematics of 8 particles at once (see :mod:`drake_tracker.core.simd.lanes`).

:func:`lane_relative_poses` computes, for the LANES configurations of a batch, the poses
of all bodies in a frame A (the camera) exactly as
:func:`~drake_tracker.core.render.kinematics.relative_poses_one` does for one, bit for bit
(tested): the same joint steps, the same products in the same order, no fused
multiply-add; only each 3x4 product acts on all lanes at once (:func:`lane_compose`).
Poses are stored as the renderer reads them: (num_bodies, 12, LANES), the rows of each
3x4 pose, lanes innermost.
"""

from __future__ import annotations

import numpy as np
from numba import njit, types
from numba.extending import intrinsic

from drake_tracker.core.simd import ir_f64 as v
from drake_tracker.core.simd.ir_f64 import WIDTH
from drake_tracker.core.simd.lanes import LANES

_HALVES = LANES // WIDTH


def _compose_codegen(q_in_lanes: bool):
    def codegen(context, b, signature, args):
        out, out_at, p, p_at, q, q_at = args
        data = [context.make_array(signature.args[k])(context, b, args[k]).data
                for k in (0, 2, 4)]
        o_d, p_d, q_d = data
        for h in range(_HALVES):
            def pv(k, h=h):
                return v.load(b, p_d, v.add_offset(b, p_at, k * LANES + h * WIDTH))

            def qv(k, h=h):  # element k of the 3x4 rows of q
                if q_in_lanes:
                    return v.load(b, q_d, v.add_offset(b, q_at, k * LANES + h * WIDTH))
                return v.splat(b, b.load(b.gep(q_d, [v.add_offset(b, q_at, k)])))

            rows = [[pv(4 * r + c) for c in range(4)] for r in range(3)]
            cols = [[qv(4 * r + c) for r in range(3)] for c in range(4)]
            for r in range(3):
                for c in range(4):
                    x = b.fadd(b.fadd(b.fmul(rows[r][0], cols[c][0]),
                                      b.fmul(rows[r][1], cols[c][1])),
                               b.fmul(rows[r][2], cols[c][2]))
                    if c == 3:
                        x = b.fadd(x, rows[r][3])
                    v.store(b, x, o_d, v.add_offset(b, out_at, (4 * r + c) * LANES + h * WIDTH))
        return context.get_dummy_value()

    return codegen


@intrinsic
def lane_compose(typingctx: object, out: types.Type, out_at: types.Type, p: types.Type,
                 p_at: types.Type, q: types.Type, q_at: types.Type) -> tuple:
    """out = p o q for 3x4 rigid poses held as 12 rows of LANES (at element offsets
    ``out_at``, ``p_at``, ``q_at`` of flat float64 arrays): out[r, c] = p[r, 0] q[0, c]
    + p[r, 1] q[1, c] + p[r, 2] q[2, c] (+ p[r, 3] for c = 3), in that order."""
    return types.void(out, out_at, p, p_at, q, q_at), _compose_codegen(q_in_lanes=True)


@intrinsic
def lane_compose_fixed(typingctx: object, out: types.Type, out_at: types.Type,
                       p: types.Type, p_at: types.Type, q: types.Type,
                       q_at: types.Type) -> tuple:
    """:func:`lane_compose` with q one pose for all lanes: a 4x4 matrix, row-major, at
    element offset ``q_at`` (its rows 0-2 are used)."""
    return types.void(out, out_at, p, p_at, q, q_at), _compose_codegen(q_in_lanes=False)


@njit(cache=True, nogil=True)
def _joint_motion(T, q, first, count, q_index, axis, kind, rev, s):
    """T (12 * LANES): each lane's X_FM of joint step s (the inverse for a reversed
    joint), as kinematics._step_pose builds it; lanes past ``count`` repeat the last."""
    ax = axis[s, 0]
    ay = axis[s, 1]
    az = axis[s, 2]
    for lane in range(LANES):
        qv = q[first + min(lane, count - 1), q_index[s]]
        if rev[s]:
            qv = -qv
        if kind[s] == 0:
            sn = np.sin(qv)
            c1 = 1.0 - np.cos(qv)
            entries = (1.0 - c1 * (ay * ay + az * az), -sn * az + c1 * ax * ay,
                       sn * ay + c1 * ax * az, 0.0,
                       sn * az + c1 * ax * ay, 1.0 - c1 * (ax * ax + az * az),
                       -sn * ax + c1 * ay * az, 0.0,
                       -sn * ay + c1 * ax * az, sn * ax + c1 * ay * az,
                       1.0 - c1 * (ax * ax + ay * ay), 0.0)
        else:
            entries = (1.0, 0.0, 0.0, qv * ax, 0.0, 1.0, 0.0, qv * ay, 0.0, 0.0, 1.0, qv * az)
        for k in range(12):
            T[k * LANES + lane] = entries[k]


@njit(cache=True, nogil=True)
def lane_relative_poses(q: np.ndarray, first: int, count: int, kind: np.ndarray,
                        inboard: np.ndarray, outboard: np.ndarray, q_index: np.ndarray,
                        axis: np.ndarray, A: np.ndarray, B: np.ndarray, rev: np.ndarray,
                        frame_body: int, X_BF: np.ndarray, world: np.ndarray,
                        poses: np.ndarray, work: np.ndarray) -> None:
    """``poses`` (num_bodies, 12, LANES) = the camera-frame poses (frame A at X_BF on
    body ``frame_body``) of all bodies for configurations q[first:first + count] (lanes
    past ``count`` repeat the last one); ``world`` (num_bodies * 12 * LANES) and
    ``work`` (3 * 12 * LANES) are scratch. The joint tables are
    :meth:`~drake_tracker.core.render.kinematics.BatchedKinematics.frame_tables`'."""
    stride = 12 * LANES
    M = 0
    T = 12 * LANES
    MT = 24 * LANES
    world[:stride] = 0.0
    for r in range(3):
        world[(5 * r) * LANES:(5 * r + 1) * LANES] = 1.0  # the world body: identity
    A_flat = A.reshape(-1)
    B_flat = B.reshape(-1)
    for s in range(kind.shape[0]):
        i = inboard[s]
        o = outboard[s]
        lane_compose_fixed(work, M, world, i * stride, A_flat, s * 16)
        if kind[s] == 2:  # weld: A already holds X_PF X_FM
            lane_compose_fixed(world, o * stride, work, M, B_flat, s * 16)
            continue
        _joint_motion(work[T:MT], q, first, count, q_index, axis, kind, rev, s)
        lane_compose(work, MT, work, M, work, T)
        lane_compose_fixed(world, o * stride, work, MT, B_flat, s * 16)
    # X_WA = X_W(frame_body) X_BF, then its inverse, then every body in A
    lane_compose_fixed(work, M, world, frame_body * stride, X_BF.reshape(-1), 0)
    for r in range(3):
        for lane in range(LANES):
            m = work[M + lane:M + 12 * LANES:LANES]
            for c in range(3):
                work[T + (4 * r + c) * LANES + lane] = m[4 * c + r]
            work[T + (4 * r + 3) * LANES + lane] = -(m[r] * m[3] + m[4 + r] * m[7]
                                                     + m[8 + r] * m[11])
    flat = poses.reshape(-1)
    for body in range(poses.shape[0]):
        lane_compose(flat, body * stride, work, T, world, body * stride)

