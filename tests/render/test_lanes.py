"""SIMD across particles (core/simd/lanes.py, lane_render.py, simd_ir.py, simd_f32.py) against
plain references: libm's exp, log and erfc, and the scalar rasteriser's images."""

import math

import numpy as np
import pytest
from numba import njit, types
from numba.extending import intrinsic

from drake_tracker.core.render.batched import BatchedDepthRenderer
from drake_tracker.core.render.configurations import (
    default_view_configuration,
    random_configurations,
)
from drake_tracker.core.sensors.camera import CameraIntrinsics
from drake_tracker.core.simd import ir_f32 as simd_f32
from drake_tracker.core.simd.lane_render import lane_scratch, render_lanes
from drake_tracker.core.simd.lanes import LANES
from drake_tracker.robot.model import build_tracker_model, robot_preset


def _vector_map_f32(emit):
    """A numba function out[i:i+8] = emit(x[i:i+8]) in float32 over float32 arrays of a
    multiple of 8."""
    @intrinsic
    def apply(typingctx, x, out, i):
        def codegen(context, b, signature, args):
            x_d = context.make_array(signature.args[0])(context, b, args[0]).data
            o_d = context.make_array(signature.args[1])(context, b, args[1]).data
            ptr_type = simd_f32.VEC_F32.as_pointer()
            value = b.load(b.bitcast(b.gep(x_d, [args[2]]), ptr_type), align=4)
            b.store(emit(b, [value])[0], b.bitcast(b.gep(o_d, [args[2]]), ptr_type),
                    align=4)
            return context.get_dummy_value()

        return types.void(x, out, i), codegen

    @njit
    def run(x, out):
        for i in range(0, x.shape[0], simd_f32.WIDTH_F32):
            apply(x, out, i)

    def call(x):
        x = np.ascontiguousarray(x, dtype=np.float32)
        out = np.empty_like(x)
        run(x, out)
        return out.astype(np.float64), x.astype(np.float64)

    return call


def test_float32_exp_log_erfc_against_libm():
    """The float32 lanes' exp, log and erfc (the pixel likelihood's mixture) within a
    few float32 ulps of libm's double-precision values of the same float32 arguments."""
    rng = np.random.default_rng(1)
    limit = simd_f32.EXP_LIMIT_F32
    x = np.concatenate([rng.uniform(-limit, limit, 4000), rng.uniform(-5, 5, 3992),
                        [0.0, -0.0, 1e-30, limit, -limit, 0.5 * math.log(2.0), 1.0, -1.0]])
    got, x = _vector_map_f32(simd_f32.exp_f32)(x)
    np.testing.assert_allclose(got, np.exp(x), rtol=1e-6, atol=0)
    got, _ = _vector_map_f32(simd_f32.exp_f32)(np.array([-200.0, 200.0] * 4))
    np.testing.assert_allclose(got, [math.exp(-limit), math.exp(limit)] * 4, rtol=1e-6)
    y = np.concatenate([np.exp(rng.uniform(-80, 80, 4000)), rng.uniform(0.5, 2.0, 3992),
                        [1.0, math.sqrt(0.5), math.sqrt(2.0), 1.2e-38, 3e38, 3.0, 0.1, 7.0]])
    got, y = _vector_map_f32(simd_f32.log_f32)(y)
    assert np.max(np.abs(got - np.log(y)) / np.maximum(1.0, np.abs(np.log(y)))) < 1e-6
    x = np.concatenate([rng.uniform(-6.0, simd_f32.ERFC_Y_MAX_F32, 7992),
                        [0.0, -0.0, 1e-9, -1e-9, 9.0, -9.0, 3.0, -3.0]])
    got, x = _vector_map_f32(simd_f32.erfc_f32)(x)
    expected = np.array([math.erfc(v) for v in x])
    # exp(-y^2) inherits the float32 rounding of y^2 (half an ulp: 6e-8 y^2 relative)
    assert np.all(np.abs(got / expected - 1.0) <= 1e-6 + 2e-7 * x * x)
    far, _ = _vector_map_f32(simd_f32.erfc_f32)(np.array([10.0, 30.0, -10.0, -30.0] * 2))
    assert np.all(far[[0, 1, 4, 5]] < 1e-35) and np.all(far[[0, 1, 4, 5]] >= 0)
    assert np.all(far[[2, 3, 6, 7]] == 2.0)


def test_float32_erfcx_fit_is_accurate():
    c = simd_f32.erfcx_fit_f32()
    y = np.linspace(0.0, simd_f32.ERFC_Y_MAX_F32, 20001)
    t = 1.0 / (1.0 + 0.5 * y)
    t_lo = 1.0 / (1.0 + 0.5 * simd_f32.ERFC_Y_MAX_F32)
    s = (t - t_lo) * 2.0 / (1.0 - t_lo) - 1.0
    expected = np.array([math.exp(v * v) * math.erfc(v) for v in y])
    assert np.max(np.abs(np.polynomial.polynomial.polyval(s, c) / expected - 1)) < 5e-8


@njit
def _lane_images(poses, tables, planes, fx, fy, cx, cy, near, far, height, width, out):
    """Depth images (LANES, H, W) of a batch, from the lanes' z-buffer."""
    (vertices, triangles, part_body, part_vertex_start, part_tri_start, centers, radii,
     tri_planes, closed) = tables
    zb = np.zeros(height * width * LANES + LANES)
    rows = np.array([height, -1])
    span = np.empty((height, 2), np.int64)
    span[:, 0] = width
    span[:, 1] = -1
    render_lanes(zb, height, width, poses, vertices, triangles, part_body, part_vertex_start,
                 part_tri_start, centers, radii, tri_planes, closed, planes, fx, fy, cx, cy,
                 near, far, lane_scratch(vertices.shape[0]), rows, span)
    covered = True  # every pixel drawn lies in its row's span
    for r in range(height):
        for c in range(width):
            for lane in range(LANES):
                iz = zb[(r * width + c) * LANES + lane]
                out[lane, r, c] = np.float32(1.0 / iz) if iz > 0.0 else np.float32(np.inf)
                if iz > 0.0 and not (span[r, 0] <= c and c <= span[r, 1]):
                    covered = False
    return covered


@pytest.mark.parametrize("robot, spread", [("apollo", 0.02), ("apollo", 0.6), ("arm6", 0.3)])
def test_lane_images_equal_the_scalar_rasteriser(robot, spread):
    """Each lane of a batch gets exactly the image the scalar rasteriser renders for its
    particle, for particles as alike as a CPF block's (0.02 rad) and far apart."""
    model = build_tracker_model(robot_preset(robot))
    renderer = BatchedDepthRenderer(model, CameraIntrinsics.from_fov(640, 480, np.radians(45))
                                    .subsampled(8))
    q = random_configurations(model, 4 * LANES, seed=3, spread_rad=spread,
                              center=default_view_configuration(model))
    expected = renderer.render(q)
    X = renderer.kinematics.relative_poses(q, model.camera_frame)
    k = renderer.intrinsics
    drawn = 0
    for first in range(0, len(q), LANES):
        poses = np.ascontiguousarray(X[first:first + LANES, :, :3, :].reshape(
            LANES, X.shape[1], 12).transpose(1, 2, 0))
        got = np.empty((LANES, k.height, k.width), np.float32)
        assert _lane_images(poses, renderer._lane_tables, renderer._planes, renderer._fx,
                     renderer._fy, renderer._cx, renderer._cy, renderer.near_m,
                     renderer.far_m, k.height, k.width, got)
        want = expected[first:first + LANES]
        # the same robot pixels, at the same float32 depths
        np.testing.assert_array_equal(np.isfinite(got), np.isfinite(want))
        np.testing.assert_array_equal(got, want)
        drawn += np.isfinite(want).sum()
    assert drawn > 100 * len(q)  # the robot is in view


@pytest.mark.parametrize("robot", ["apollo", "arm6"])
def test_lane_forward_kinematics_is_the_scalar_one_bit_for_bit(robot):
    """lane_relative_poses against BatchedKinematics.relative_poses (kinematics.py's
    relative_poses_one per particle), a full batch and a short one (lanes past the
    count repeat the last configuration)."""
    from drake_tracker.core.render.kinematics import BatchedKinematics
    from drake_tracker.core.simd.lane_kinematics import lane_relative_poses

    model = build_tracker_model(robot_preset(robot))
    kinematics = BatchedKinematics.from_plant(model.plant)
    q = random_configurations(model, LANES + 5, seed=1, spread_rad=0.5,
                              center=default_view_configuration(model))
    expected = kinematics.relative_poses(q, model.camera_frame)
    nb = kinematics.num_bodies
    world, work = np.zeros(nb * 12 * LANES), np.zeros(3 * 12 * LANES)
    for first in (0, LANES):
        count = min(LANES, len(q) - first)
        poses = np.zeros((nb, 12, LANES))
        lane_relative_poses(q, first, count, *kinematics.frame_tables(model.camera_frame),
                            world, poses, work)
        for lane in range(LANES):
            n = first + min(lane, count - 1)
            np.testing.assert_array_equal(poses[:, :, lane].reshape(nb, 3, 4),
                                          expected[n, :, :3, :])


def test_the_kept_workspace_is_left_clear_between_calls():
    """The scoring kernel's z-buffers and spans, kept by the renderer between calls, are
    all zeros and empty after every call (the kernel clears what it drew, the torso's
    clipped triangles included), so each call scores as a fresh workspace would."""
    from drake_tracker.core.likelihood.pixel_model import LikelihoodParams, prepare_observation
    from drake_tracker.core.render.configurations import synthetic_observation

    model = build_tracker_model(robot_preset("apollo"))
    renderer = BatchedDepthRenderer(model, CameraIntrinsics.from_fov(80, 60, np.radians(45)))
    center = default_view_configuration(model)
    observation = prepare_observation(synthetic_observation(renderer, center),
                                      LikelihoodParams())
    q = random_configurations(model, 2 * LANES + 3, seed=5, spread_rad=0.3, center=center)
    first = renderer.score(q, observation)
    zb, span = renderer.workspace(1)[:2]
    assert not zb.any()
    assert np.all(span[:, :, 0] == renderer.intrinsics.width) and np.all(span[:, :, 1] == -1)
    renderer._workspace = None  # a fresh one
    np.testing.assert_array_equal(renderer.score(q, observation), first)
    # other batch companions: the same to rounding (the pixels' order of summation)
    np.testing.assert_allclose(renderer.score(q[::-1], observation), first[::-1], rtol=1e-13)
