"""The simulated camera's fast path (``camera.render_stride``): it renders only the pixels
the subsampled image keeps and their full-resolution neighbours, and delivers what the
full-resolution camera followed by ``subsample`` delivers."""

import dataclasses

import numpy as np
import pytest
from pydrake.geometry import ColorRenderCamera
from pydrake.math import RigidTransform

from drake_tracker.core.sensors.camera import subsample
from drake_tracker.sim.depth_camera import (
    camera_intrinsics,
    corrupt_depth,
    depth_render_camera,
    rendered_intrinsics,
)
from drake_tracker.sim.record import simulate_and_record
from drake_tracker.sim.scenario.load import load_scenario, validate_scenario
from drake_tracker.sim.world import build_simulated_world

STRIDE = 8
#: Scene times of the occlusion scenario: arm, table, wall and the box in view.
TIMES_S = (0.0, 3.0, 7.0)


@pytest.fixture(scope="module")
def renders():
    """Per time: the full render, the subsampled grid, the kept rows at full width, the
    kept columns at full height (depth, m), and the label images (full and grid)."""
    scenario = load_scenario("occlusion/constant")
    diagram, world = build_simulated_world(scenario)
    context = diagram.CreateDefaultContext()
    frame = world.plant.GetBodyFrameIdOrThrow(world.camera_frame.body().index())
    config = scenario.camera
    cameras = {"full": (1, 1), "grid": (STRIDE, STRIDE), "rows": (1, STRIDE),
               "columns": (STRIDE, 1)}
    out = []
    for t in TIMES_S:
        context.SetTime(t)
        query = diagram.GetOutputPort("query_object").Eval(context)
        images = {name: np.array(query.RenderDepthImage(
            depth_render_camera(config, strides=strides), frame, RigidTransform()).data[:, :, 0])
            for name, strides in cameras.items()}
        for name in ("full", "grid"):
            core = depth_render_camera(config, strides=cameras[name]).core()
            images[f"{name}_labels"] = np.array(query.RenderLabelImage(
                ColorRenderCamera(core, False), frame, RigidTransform()).data[:, :, 0])
        out.append(images)
    return config, out


def test_the_grid_render_is_the_full_render_at_the_kept_pixels(renders):
    _, images = renders
    for im in images:
        full, grid = subsample(im["full"], STRIDE), im["grid"]
        assert grid.shape == full.shape == (60, 80)
        np.testing.assert_array_equal(np.isfinite(grid), np.isfinite(full))
        hit = np.isfinite(full)
        assert 0.1 < hit.mean() and np.abs(grid[hit] - full[hit]).max() < 1e-4
        labels = subsample(im["full_labels"], STRIDE)
        np.testing.assert_array_equal(im["grid_labels"], labels)
        assert len(np.unique(labels)) >= 3  # robot bodies and background


def test_row_and_column_renders_are_the_full_render_at_their_pixels(renders):
    # A pixel centre exactly on a triangle's edge may fall on either side (one pixel of
    # 38400 was seen to); every other pixel agrees to float precision.
    _, images = renders
    for im in images:
        for name, full in (("rows", im["full"][::STRIDE, :]),
                           ("columns", im["full"][:, ::STRIDE])):
            render = im[name]
            assert render.shape == full.shape
            same = (np.isfinite(render) == np.isfinite(full)) & ~(
                np.abs(render - full) > 1e-4)
            assert same.mean() > 0.999, name


def test_the_strided_sensor_model_has_the_full_resolution_silhouettes(renders):
    config, images = renders
    # Without noise and dropout the sensor model is its silhouettes and no-hits alone.
    quiet = dataclasses.replace(config, noise_sigma0_m=0.0, noise_k_per_m=0.0,
                                dropout_probability=0.0)
    strided = dataclasses.replace(quiet, render_stride=STRIDE)
    for k, im in enumerate(images):
        reference = subsample(corrupt_depth(im["full"], quiet, 0, k), STRIDE)
        fast = corrupt_depth(im["rows"], strided, 0, k, columns_m=im["columns"])
        assert fast.shape == reference.shape
        silhouettes = np.isnan(reference) & np.isfinite(im["grid"])
        assert silhouettes.sum() > 20  # the test sees edges
        agree = (np.isnan(fast) == np.isnan(reference)).mean()
        assert agree > 0.999  # all 4800 pixels agreed here (drake 1.51.1)
        both = np.isfinite(fast) & np.isfinite(reference)
        assert np.abs(fast[both] - reference[both]).max() < 1e-4


def test_the_strided_noise_follows_the_sensor_model(renders):
    config, images = renders
    noisy_config = dataclasses.replace(config, render_stride=STRIDE, noise_sigma0_m=0.002,
                                       noise_k_per_m=0.003, dropout_probability=0.05)
    quiet = dataclasses.replace(noisy_config, noise_sigma0_m=0.0, noise_k_per_m=0.0,
                                dropout_probability=0.0)
    im = images[1]
    clean = corrupt_depth(im["rows"], quiet, 0, 0, columns_m=im["columns"])
    valid = np.isfinite(clean)
    sigma = 0.002 + 0.003 * clean[valid].astype(float) ** 2
    residuals, dropped = [], []
    for seed in range(12):
        noisy = corrupt_depth(im["rows"], noisy_config, seed, 0, columns_m=im["columns"])
        assert np.all(np.isnan(noisy[~valid]))  # silhouettes and no-hits stay invalid
        z = noisy[valid].astype(float)
        dropped.append(np.isnan(z))
        residuals.append(((z - clean[valid]) / sigma)[~np.isnan(z)])
    r = np.concatenate(residuals)
    assert len(r) > 30000
    assert abs(np.mean(r)) < 0.02 and np.std(r) == pytest.approx(1.0, abs=0.02)
    assert np.mean(np.concatenate(dropped)) == pytest.approx(0.05, abs=0.005)


def test_recorded_runs_keep_their_format_with_render_stride():
    base = load_scenario("s-full-arm/constant")
    fast = load_scenario("s-full-arm/constant")
    fast.camera.render_stride = STRIDE
    validate_scenario(fast)
    _, world = build_simulated_world(fast)
    assert world.intrinsics == rendered_intrinsics(fast.camera)
    assert world.intrinsics == camera_intrinsics(base.camera).subsampled(STRIDE)
    runs = [simulate_and_record(s, duration_s=0.2, image_stride=STRIDE) for s in (base, fast)]
    assert runs[0].camera_intrinsics == runs[1].camera_intrinsics
    assert runs[0].depth_images_m.shape == runs[1].depth_images_m.shape
    assert len(runs[0].image_capture_times_s) >= 4
    np.testing.assert_array_equal(runs[0].image_capture_times_s, runs[1].image_capture_times_s)
    # Same scene, same silhouettes; only the noise and the 0.5 % dropout are drawn anew.
    same_validity = np.mean(np.isnan(runs[0].depth_images_m) == np.isnan(runs[1].depth_images_m))
    assert same_validity > 0.98
    with pytest.raises(ValueError, match="render_stride"):
        simulate_and_record(fast, duration_s=0.1, image_stride=4)


@pytest.mark.parametrize("value", [0, 2.5, True, 481])
def test_bad_render_stride_is_rejected_by_name(value):
    s = load_scenario("s-full-arm/constant")
    s.camera.render_stride = value
    with pytest.raises(ValueError, match=r"camera\.render_stride"):
        validate_scenario(s)

