"""Issue 14's remaining faults: bounded timing records, depth images in the wrong units or
without a valid pixel, and replays of recordings with bad samples."""

import logging
import re
from dataclasses import replace

import numpy as np
import pytest
from fast_params import small_params
from pydrake.systems.analysis import Simulator

from drake_tracker.core.cpf.image_update import RECENT_UPDATES, StageTimes
from drake_tracker.core.filter.belief_buffer import ImageAnchor
from drake_tracker.core.filter.start import new_bank_and_belief
from drake_tracker.core.sensors.depth_frames import DepthFrame
from drake_tracker.core.sensors.depth_units import depth_units_problem
from drake_tracker.io.replay import replay_run
from drake_tracker.io.synthetic import synthetic_run
from drake_tracker.params.resolve import resolve_tracker_params
from drake_tracker.params.tracker_params import TrackerParams
from drake_tracker.params.validation import validate_tracker_params
from drake_tracker.systems.cpf_system import CpfImageUpdateSystem
from drake_tracker.systems.messages import ImagePrior
from drake_tracker.tracker import Tracker


def test_the_per_update_timing_record_is_bounded():
    """Finding 10: the per-update timing list grew by one float per image, forever."""
    times = StageTimes()
    for k in range(RECENT_UPDATES + 500):
        times.per_update.append(float(k))
    assert len(times.per_update) == RECENT_UPDATES
    assert times.per_update[-1] == RECENT_UPDATES + 499  # the latest are kept


# ----------------------------------------------------------------- depth images
@pytest.fixture(scope="module")
def run(apollo):
    return synthetic_run(apollo, duration_s=0.3, encoder_rate_hz=200.0, seed=3)


def started_tracker(apollo, run) -> Tracker:
    tracker = Tracker(apollo, run.camera_intrinsics, small_params())
    for t, reading in zip(run.reading_times_s, run.readings_rad, strict=True):
        tracker.add_reading(t, reading)
    return tracker


def test_a_millimetre_or_negative_image_is_a_clear_error(apollo, run):
    """Finding 5: a float image in millimetres was silently useless (every pixel beyond
    the likelihood's range); a negative one was silently used."""
    tracker = started_tracker(apollo, run)
    metres = run.depth_images_m[3]
    assert depth_units_problem(metres) is None
    before = tracker.estimate().positions.copy()
    with pytest.raises(ValueError, match="millimetres"):
        tracker.add_image(DepthFrame(0.1, 0.15, metres * 1000.0, 3))
    negative = metres.copy()
    negative[10, 10] = -0.5
    with pytest.raises(ValueError, match="negative depth"):
        tracker.add_image(DepthFrame(0.1, 0.15, negative, 3))
    np.testing.assert_array_equal(tracker.estimate().positions, before)
    assert tracker.add_image(DepthFrame(0.1, 0.15, metres, 3))


def test_the_placeholder_is_a_warned_skip_and_a_negative_sequence_a_clear_error(
        apollo, run, caplog):
    """The survey's last silent skip: an image numbered -1 (the placeholder's number)
    was ignored without a word. Now the placeholder itself is skipped with a warning,
    and real pixels under its number are a clear error; neither changes the belief."""
    tracker = started_tracker(apollo, run)
    before = tracker.estimate().positions.copy()
    with caplog.at_level(logging.WARNING):
        assert not tracker.add_image(DepthFrame.empty())
    assert "empty placeholder" in caplog.text
    with pytest.raises(ValueError, match="sequence -1"):
        tracker.add_image(DepthFrame(0.1, 0.15, run.depth_images_m[3], -1))
    np.testing.assert_array_equal(tracker.estimate().positions, before)
    assert tracker.add_image(DepthFrame(0.1, 0.15, run.depth_images_m[3], 0))


@pytest.mark.parametrize("fault", ["all zero", "all NaN", "NaN stamp"])
def test_images_without_a_valid_pixel_or_stamp_are_skipped_with_a_warning(
        apollo, run, caplog, fault):
    tracker = started_tracker(apollo, run)
    image = {"all zero": np.zeros_like(run.depth_images_m[3]),
             "all NaN": np.full_like(run.depth_images_m[3], np.nan)}.get(
                 fault, run.depth_images_m[3])
    stamp = np.nan if fault == "NaN stamp" else 0.1
    before = tracker.estimate().positions.copy()
    with caplog.at_level(logging.WARNING):
        assert not tracker.add_image(DepthFrame(stamp, 0.15, image, 3))
    assert "image 3 skipped" in caplog.text
    assert ("not finite" if fault == "NaN stamp" else "no valid depth pixel") in caplog.text
    np.testing.assert_array_equal(tracker.estimate().positions, before)


def test_cpf_system_skips_a_millimetre_image_with_a_warning(apollo, run, caplog):
    """Inside a Diagram a bad image is a rate-limited warning, never an exception."""
    p = small_params()
    system = CpfImageUpdateSystem(model=apollo, camera=run.camera_intrinsics, params=p,
                                  period_s=0.01)
    context = system.CreateDefaultContext()
    _, belief = new_bank_and_belief(resolve_tracker_params(p, apollo), run.readings_rad[0])
    anchor = ImageAnchor(0.0, 0.0, belief, np.zeros(apollo.num_joints))
    system.GetInputPort("image_prior").FixValue(context, ImagePrior(0, 0.0, anchor, ""))
    system.GetInputPort("depth_frame").FixValue(
        context, DepthFrame(0.0, 0.05, run.depth_images_m[0] * 1000.0, 0))
    with caplog.at_level(logging.WARNING):
        Simulator(system, context).AdvanceTo(0.015)
    assert "image 0 skipped" in caplog.text and "millimetres" in caplog.text
    assert system.GetOutputPort("image_observation").Eval(context).id == 0


# ----------------------------------------------------------------- replays
def test_a_replay_skips_bad_samples_with_their_time_and_finishes(apollo, run, caplog):
    """Finding 8: one NaN reading aborted the whole replay, with no time stamp given."""
    readings = run.readings_rad.copy()
    readings[21] = np.nan
    images = run.depth_images_m.copy()
    images[4] *= 1000.0
    bad = replace(run, readings_rad=readings, depth_images_m=images)
    with caplog.at_level(logging.WARNING):
        result = replay_run(bad, small_params(), apollo)
    assert f"{run.reading_times_s[21]:.4f} s is not finite" in caplog.text
    assert f"image 4 captured at {run.image_capture_times_s[4]:.4f} s skipped" in caplog.text
    assert result.num_images_applied == len(run.image_capture_times_s) - 1
    assert np.all(np.isfinite(result.positions[-5:]))


# ----------------------------------------------------------------- parameters
@pytest.mark.parametrize("field, setter", [
    ("kalman.robot_joints.angle_process_std_rad_per_sqrt_s",
     lambda p: setattr(p.kalman.robot_joints, "angle_process_std_rad_per_sqrt_s", 1e200)),
    ("image.seed", lambda p: setattr(p.image, "seed", -1)),
    ("initial_positions_rad[arm_joint_1]",
     lambda p: p.initial_positions_rad.update(arm_joint_1=float("nan"))),
    ("buffer_horizon_s", lambda p: setattr(p, "buffer_horizon_s", float("inf"))),
])
def test_parameters_that_would_fail_later_are_rejected_at_load_by_name(field, setter):
    """Finding 6 (the part in params.py): these loaded, then failed at the first image or
    silently disabled the buffer's pruning."""
    p = TrackerParams()
    setter(p)
    with pytest.raises(ValueError, match=re.escape(field)):
        validate_tracker_params(p)


def test_unknown_joint_names_are_reported_when_the_tracker_is_built(apollo, run):
    """Finding 9: reported at the first reading, not when the parameters were given."""
    p = small_params()
    p.initial_positions_rad["no_such_joint"] = 0.1
    with pytest.raises(ValueError, match="no_such_joint"):
        Tracker(apollo, run.camera_intrinsics, p)
