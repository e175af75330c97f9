"""Images that show no arm where one must be are skipped, offline and in the Diagram.

While the tracker holds the arm, an image that sees through (almost) all of the arm both
where the estimate renders it and where the encoders do cannot be explained by any bias:
the arm is not in it (a moved camera, a stale or foreign frame). Updated, one such image
swung the estimate 570 mm to put the arm out of view (the fault matrix's
arm_out_of_view). It is skipped, with a warning, and counted by the health as a
disagreement.
"""

import logging
from dataclasses import replace

import numpy as np
from fast_params import small_params
from offline_vs_diagram import feed

from drake_tracker.core.filter.estimate import PoseReadout
from drake_tracker.core.robustness.health import HealthState
from drake_tracker.io.synthetic import synthetic_run
from drake_tracker.metrics import pose_errors
from drake_tracker.tracker import Tracker

NO_ARM_FROM_S, NO_ARM_TO_S = 0.9, 1.2


def _run_with_images_without_the_arm(apollo):
    """A synthetic run whose images in [0.9, 1.2) s show the background (a wall at 2.5 m,
    2 mm of noise) and no arm."""
    run = synthetic_run(apollo, duration_s=1.6, encoder_rate_hz=200.0, seed=3,
                        bias_rad=np.radians(2.0))
    images = run.depth_images_m.copy()
    gone = (run.image_capture_times_s >= NO_ARM_FROM_S) & (
        run.image_capture_times_s < NO_ARM_TO_S)
    noise = np.random.default_rng(11).normal(0.0, 0.002, images[gone].shape)
    images[gone] = (2.5 + noise).astype(images.dtype)
    return replace(run, depth_images_m=images), gone


def test_images_without_the_arm_are_skipped_and_the_estimate_holds(apollo, caplog):
    run, gone = _run_with_images_without_the_arm(apollo)
    p = small_params()
    clean_tracker = Tracker(apollo, run.camera_intrinsics, p)
    clean, _ = feed(clean_tracker, synthetic_run(apollo, duration_s=1.6, seed=3,
                                                 encoder_rate_hz=200.0,
                                                 bias_rad=np.radians(2.0)))
    tracker = Tracker(apollo, run.camera_intrinsics, p)
    with caplog.at_level(logging.WARNING):
        estimates, applied = feed(tracker, run)
    assert "no arm where one must be" in caplog.text
    skipped = [i for i in np.flatnonzero(gone) if i in applied and not applied[i]]
    assert len(skipped) >= 2, applied
    # The hand where the clean run has it, within 20 mm, through the gap and after.
    during = np.flatnonzero(run.reading_times_s >= NO_ARM_FROM_S)
    readout = PoseReadout(apollo)
    hand = readout.poses(np.array([estimates[k] for k in during]))[0]
    clean_hand = readout.poses(np.array([clean[k] for k in during]))[0]
    assert np.max(pose_errors(hand, clean_hand)[0]) < 20.0
    assert tracker.health.state == HealthState.TRACKING  # back once the arm is


