"""Subsampled intrinsics describe the kept pixels: Drake's own render at the subsampled
intrinsics equals its full-resolution render subsampled."""

import numpy as np

from drake_tracker.core.render.backends import make_renderer
from drake_tracker.core.render.configurations import default_view_configuration
from drake_tracker.core.sensors.camera import CameraIntrinsics, subsample
from drake_tracker.robot.model import build_tracker_model, robot_preset


def test_subsampled_intrinsics_match_subsampled_drake_render():
    model = build_tracker_model(robot_preset("apollo"))
    full = CameraIntrinsics.from_fov(640, 480, np.radians(45.0))
    q = default_view_configuration(model)[None]
    big = subsample(make_renderer(model, full, "drake").render(q)[0], 8)
    small = make_renderer(model, full.subsampled(8), "drake").render(q)[0]
    hit_big, hit_small = np.isfinite(big), np.isfinite(small)
    assert hit_big.sum() > 200
    mismatch = (hit_big ^ hit_small).sum() / (hit_big | hit_small).sum()
    assert mismatch < 0.01, mismatch
    both = hit_big & hit_small
    assert np.median(np.abs(big[both] - small[both])) < 1e-4
    # Without the principal-point shift the rays are 3.5 full pixels apart.
    unshifted = CameraIntrinsics(80, 60, full.fx / 8, full.fy / 8, full.cx / 8, full.cy / 8)
    wrong = make_renderer(model, unshifted, "drake").render(q)[0]
    wrong_mismatch = (hit_big ^ np.isfinite(wrong)).sum() / (hit_big | np.isfinite(wrong)).sum()
    assert wrong_mismatch > 2 * mismatch
