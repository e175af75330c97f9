"""The batched numba renderer against Drake's RenderEngineVtk, on the same poses."""

import numpy as np
import pytest

from drake_tracker.bench.renderers import benchmark_renderers
from drake_tracker.core.render.backends import make_renderer
from drake_tracker.core.render.batched import BatchedDepthRenderer
from drake_tracker.core.render.configurations import (
    default_view_configuration,
    random_configurations,
)
from drake_tracker.core.sensors.camera import CameraIntrinsics
from drake_tracker.robot.model import build_tracker_model, robot_preset

FULL = CameraIntrinsics.from_fov(640, 480, np.radians(45))
NUM_CONFIGURATIONS = 20


@pytest.fixture(scope="module", params=["apollo", "arm6"])
def model(request):
    return build_tracker_model(robot_preset(request.param))


@pytest.fixture(scope="module")
def configurations(model):
    return random_configurations(model, NUM_CONFIGURATIONS, seed=7,
                                 center=default_view_configuration(model))


def _compare(a: np.ndarray, b: np.ndarray) -> dict:
    hit_a, hit_b = np.isfinite(a), np.isfinite(b)
    either = hit_a | hit_b
    both = hit_a & hit_b
    diff = np.abs(a[both].astype(float) - b[both].astype(float))
    return {
        "either": int(either.sum()),
        "both": int(both.sum()),
        "mismatch": float((hit_a ^ hit_b).sum() / max(1, either.sum())),
        "median": float(np.median(diff)) if diff.size else 0.0,
        "p95": float(np.percentile(diff, 95)) if diff.size else 0.0,
    }


@pytest.mark.parametrize("stride", [8, 2], ids=["80x60", "320x240"])
def test_batched_matches_drake_vtk(model, configurations, stride):
    intrinsics = FULL.subsampled(stride)
    batched = make_renderer(model, intrinsics, "batched")
    drake = make_renderer(model, intrinsics, "drake")
    ours = batched.render(configurations)
    ref = drake.render(configurations)
    assert ours.shape == ref.shape == (NUM_CONFIGURATIONS, intrinsics.height, intrinsics.width)
    assert ours.dtype == np.float32
    stats = _compare(ours, ref)
    # The configurations must actually show the robot for the comparison to mean anything.
    assert stats["both"] > 0.03 * ours.size, stats
    assert stats["mismatch"] <= 0.02, stats
    assert stats["median"] <= 0.001, stats
    assert stats["p95"] <= 0.005, stats


def test_render_is_deterministic_and_batch_independent(model, configurations):
    renderer = BatchedDepthRenderer(model, FULL.subsampled(8))
    all_at_once = renderer.render(configurations)
    one_by_one = np.stack([renderer.render(q)[0] for q in configurations])
    np.testing.assert_array_equal(all_at_once, one_by_one)
    assert renderer.render(configurations[:0]).shape == (0, 60, 80)


def test_benchmark_reports_the_documented_keys(model):
    result = benchmark_renderers(model, FULL.subsampled(8), num_particles=20, num_drake=5)
    for key in ("batched_us_per_image", "drake_us_per_image", "renderer_speedup_vs_drake"):
        assert np.isfinite(result[key]) and result[key] > 0
    assert result["hit_mismatch_fraction"] <= 0.02


def _observation_of(renderer, q_true, rng, background_m=2.5):
    """A noisy depth image of q_true in front of a wall, with a box occluding a patch."""
    depth = renderer.render(q_true)[0].astype(np.float64)
    depth[~np.isfinite(depth)] = background_m
    depth += rng.normal(0.0, 0.004, size=depth.shape)
    h, w = depth.shape
    depth[h // 3:h // 2, w // 3:w // 2] = 0.6  # occluder in front of everything
    depth[:2, :] = np.nan  # invalid pixels
    depth[-1, :5] = 9.0  # beyond Z_max
    return depth.astype(np.float32)


@pytest.mark.parametrize("stride", [8, 4], ids=["80x60", "160x120"])
def test_fused_render_likelihood_equals_render_then_likelihood(model, configurations, stride):
    from drake_tracker.core.likelihood.pixel_model import (
        LikelihoodParams,
        log_likelihoods,
        prepare_observation,
    )
    from drake_tracker.core.simd.lane_likelihood import SCORE_ATOL_PER_PIXEL

    renderer = BatchedDepthRenderer(model, FULL.subsampled(stride))
    rng = np.random.default_rng(3)
    q_true = default_view_configuration(model)
    q = np.vstack([q_true, configurations,
                   q_true + rng.normal(0.0, 0.03, size=(40, len(q_true)))])
    for params in (LikelihoodParams(), LikelihoodParams(
            tail_weight=0.05, depth_noise_std_m=0.01, depth_noise_factor_per_m=0.0,
            occluder_rate_per_m=2.0, occlusion_probability=0.3)):
        observation = prepare_observation(_observation_of(renderer, q_true, rng), params)
        expected = log_likelihoods(renderer.render(q), observation, params)
        fused = renderer.score(q, observation)
        assert fused.shape == (len(q),)
        assert np.ptp(expected) > 1.0  # the particles are actually told apart
        # Stated tolerance: the kernel's pixel terms are float32, summed in double over
        # the pixels where the particle's robot is drawn.
        robot_pixels = np.isfinite(renderer.render(q)).sum(axis=(1, 2))
        assert np.all(np.abs(fused - expected) <= SCORE_ATOL_PER_PIXEL * robot_pixels)
        # Particles are independent of their batch.
        np.testing.assert_allclose(renderer.score(q[5:9], observation), fused[5:9],
                                   rtol=1e-12)
    assert renderer.score(q[:0], observation).shape == (0,)
    with pytest.raises(ValueError, match="shape"):
        wrong = prepare_observation(np.ones((7, 9), np.float32), LikelihoodParams())
        renderer.score(q, wrong)


def test_culling_does_not_change_the_images(model):
    """Back-face and frustum culling are exact: the same images with culling disabled
    (no triangle marked closed, bounding spheres that never leave the frustum), for
    configurations spread widely enough to put parts out of view and near the camera."""
    from dataclasses import replace

    from drake_tracker.core.render.mesh_parts import render_tables

    intrinsics = FULL.subsampled(8)
    culled = BatchedDepthRenderer(model, intrinsics)
    plain = BatchedDepthRenderer(model, intrinsics)
    tables = list(render_tables(replace(plain.meshes, triangle_closed=None),
                                 plain.kinematics.num_bodies))
    tables[6] = np.full_like(tables[6], 1e6)  # bounding-sphere radii
    plain._tables = tuple(tables)
    q = random_configurations(model, 200, seed=11, spread_rad=1.0,
                              center=default_view_configuration(model))
    np.testing.assert_array_equal(culled.render(q), plain.render(q))


def test_mesh_parts_partition_each_body_and_render_the_same_images(model):
    """Every triangle is in exactly one part, of its own body, with at most the
    requested number of triangles and a sphere that holds its vertices; the images do not
    depend on how the bodies are split."""
    from drake_tracker.core.render.mesh_parts import render_tables

    renderer = BatchedDepthRenderer(model, FULL.subsampled(8))
    meshes, nb = renderer.meshes, renderer.kinematics.num_bodies
    vertices, triangles, part_body, v_start, t_start, centers, radii = \
        render_tables(meshes, nb, max_triangles=7)[:7]
    sizes = np.diff(t_start)
    assert sizes.sum() == meshes.num_triangles and sizes.max() <= 7 and sizes.min() >= 1
    corners = np.sort(vertices[triangles].reshape(-1, 9), axis=1)
    source = np.sort(np.asarray(meshes.vertices)[meshes.triangles].reshape(-1, 9), axis=1)
    np.testing.assert_array_equal(np.unique(corners, axis=0), np.unique(source, axis=0))
    for p in range(len(part_body)):
        tris = triangles[t_start[p]:t_start[p + 1]]
        assert tris.min() >= v_start[p] and tris.max() < v_start[p + 1]
        own = vertices[v_start[p]:v_start[p + 1]]
        assert np.all(np.linalg.norm(own - centers[p], axis=1) <= radii[p])
    assert np.bincount(part_body, sizes, nb).astype(int).tolist() == \
        np.bincount(meshes.triangle_body, minlength=nb).tolist()
    q = random_configurations(model, 50, seed=12, spread_rad=0.5,
                              center=default_view_configuration(model))
    reference = renderer.render(q)
    for max_triangles in (1, 7, 10**9):
        renderer._tables = render_tables(meshes, nb, max_triangles)
        np.testing.assert_array_equal(renderer.render(q), reference)


def test_small_box_rasterisation_equals_the_row_runs():
    """The per-pixel test of small triangles' boxes writes exactly the pixels, depths and
    rows that the per-row runs of columns write: 3000 random triangles (many small, some
    large, slivers, some crossing the depth range) rasterised with every triangle on
    either path give the same z-buffer and rows, and spans that cover the pixels."""
    from numba import njit

    from drake_tracker.core.render.rasterize import _raster

    @njit
    def raster_all(uv_iz, box_px, H, W):
        zbuf = np.zeros((H, W))
        rows = np.array([H, -1])
        span = np.empty((H, 2), dtype=np.int64)
        span[:, 0] = W
        span[:, 1] = -1
        for t in range(uv_iz.shape[0]):
            a = uv_iz[t]
            _raster(zbuf, a[0], a[1], a[2], a[3], a[4], a[5], a[6], a[7], a[8],
                    0.1, 6.0, rows, span, box_px)
        return zbuf, rows, span

    rng = np.random.default_rng(5)
    H, W = 60, 80
    centre = rng.uniform([-5, -5], [W + 5, H + 5], (3000, 1, 2))
    scale = np.exp(rng.uniform(np.log(0.3), np.log(30.0), (3000, 1, 1)))
    uv = centre + scale * rng.normal(size=(3000, 3, 2))
    iz = 1.0 / rng.uniform(0.05, 7.0, (3000, 3, 1))  # some outside [near, far]
    uv_iz = np.ascontiguousarray(np.concatenate([uv, iz], axis=2).reshape(3000, 9))
    rows_z, rows_r, rows_s = raster_all(uv_iz, 0, H, W)
    box_z, box_r, box_s = raster_all(uv_iz, 10**9, H, W)
    assert (rows_z > 0).sum() > 0.5 * H * W
    np.testing.assert_array_equal(box_z, rows_z)
    np.testing.assert_array_equal(box_r, rows_r)
    written = np.argwhere(box_z > 0)
    assert np.all(box_s[written[:, 0], 0] <= written[:, 1])
    assert np.all(box_s[written[:, 0], 1] >= written[:, 1])
