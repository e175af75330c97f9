"""Issue 14's fault matrix: each sensor fault injected into one simulated run of the
default scenario (``s-full-arm/constant``: 8.6 deg constant bias on every arm joint, the
camera 2 cm / 2.6 deg off its nominal mounting), replayed through the offline
``Tracker`` and compared with the clean replay of the same run.

Each fault starts at ``FAULT_START_S`` (the tracker has acquired the arm by 1.5 s) and
every test asserts that

* the estimate stays finite at every ground-truth sample (100 Hz);
* the hand's translation error stays within the fault's bound (``BOUND_MM``) from the
  fault's start to 4 s after its end. A fault that loses no data (a glitched stamp, a
  clock step, images out of order or in a burst) must keep full-fusion accuracy:
  ``LOSSLESS_MM`` (15 mm, three times the clean replay's largest error after
  acquisition, 5 mm). A fault that withholds data (no images, unusable images, an
  occluded arm, no or non-finite readings) leaves the tracker on the encoders, its bias
  estimate (which relaxes towards zero without images, by design) and the latest
  reading: its error must stay below the encoders' alone on the same data at every
  sample (about 160-340 mm here), and below the bound in ``BOUND_MM`` (the largest
  figure measured plus about 40 %, so a regression shows);
* full-fusion accuracy is back 3 s after the fault ends: the median error over
  [end + 3 s, end + 4 s] is within ``RECOVERY_SLACK_MM`` of the clean replay's median
  over the same second (0.8-3.5 mm; the largest excess measured is 1.0 mm, after the
  occlusion).

The arm vanishing from the images while the encoders say it is in view (background-only
images for 1 s) withholds data too: such images are skipped (``shows_no_arm``).
Before that check it was an ``xfail``: one of them swung the estimate 570 mm to put the
arm out of view, and the restart from the encoders that followed ended 190-340 mm off.
With the check of far-future stamps disabled (``StreamClock.future_limit_s`` infinite),
the glitched-stamp case fails (224 mm); with the reading-gap check disabled, the NaN-burst
and no-readings cases still pass (the bounds do not see that difference).

A camera whose sequence counter restarts is a Diagram matter (the offline tracker takes
no sequence numbers for anything but messages): it is tested in the Diagram by
``tests/faults/test_timestamps.py::test_diagram_survives_glitch_step_restart_and_order_like_the_offline_tracker``.

One 16 s recording (the 10 s image outage needs 4 s after it) is simulated per module;
the faulted replays start from a snapshot of the clean replay's tracker at the fault's
start and stop 4 s after its end. Image updates use ``small_params()`` at the default
image rate (10/s).
"""

import copy
import logging
from dataclasses import replace

import numpy as np
import pytest
from fast_params import small_params

from drake_tracker.core.sensors.depth_frames import DepthFrame
from drake_tracker.demo.run import DEFAULT_SCENARIO, render_what_the_tracker_reads
from drake_tracker.io.replay import encoders_only_X_CE
from drake_tracker.metrics import pose_errors
from drake_tracker.params.tracker_params import TrackerParams
from drake_tracker.sim.record import simulate_and_record
from drake_tracker.sim.scenario.load import load_scenario
from drake_tracker.tracker import Tracker

FAULT_START_S = 2.0
IMAGE_OUTAGE_S = 10.0
RECORD_S = FAULT_START_S + IMAGE_OUTAGE_S + 4.0
LOSSLESS_MM = 15.0
RECOVERY_SLACK_MM = 2.0
#: Faults that withhold data: error bound (mm) from the fault's start on. In brackets the
#: largest error measured at 8b9ed24, then at 9e7fa4d (bias defaults σb = 0.0088,
#: c = 0.98 instead of 0.02, 0.9: the bias is held longer without images; and the level
#: of detail of 5e4828a): the bounds are about 1.4 times the larger.
BOUND_MM = {
    "no_images": 160.0,  # (115, 37) 10 s without images: the bias estimate relaxes
    "arm_out_of_view": 40.0,  # (-, 25.1) as no images for 1 s (the images are skipped)
    "full_occlusion": 80.0,  # (58, 19)
    "no_readings": 250.0,  # (182, 182) the arm moves on, the estimate waits for a reading
    "nan_burst": 100.0,  # (74, 74)
    # (45, 14; then 25.9 once 5 images in the readings' "gap" re-align the images: they
    # were skipped for the whole 1 s the step left, 44.6 just before)
    "encoder_clock_step_+1s": 40.0,
    "all_NaN_images": 40.0,  # (25, 9.5)
    "all_zero_images": 40.0,  # (25, 9.5)
    "millimetres_images": 40.0,  # (25, 9.5)
}


def fast_params() -> TrackerParams:
    """``small_params()`` at the default image rate (10 images/s) and update latency (on
    the worker thread in a Diagram)."""
    p = small_params()
    p.image.min_image_interval_s = TrackerParams().image.min_image_interval_s
    p.image.update_latency_s = TrackerParams().image.update_latency_s
    return p


@pytest.fixture(scope="module")
def scenario():
    return render_what_the_tracker_reads(load_scenario(DEFAULT_SCENARIO), fast_params())


@pytest.fixture(scope="module")
def recorded(scenario):
    """The default scenario, simulated for ``RECORD_S`` (seeded by the scenario)."""
    return simulate_and_record(scenario, duration_s=RECORD_S,
                               image_stride=scenario.camera.render_stride, validate=False)


@pytest.fixture(scope="module")
def background(scenario):
    """Depth images of the same camera with the arm swung out of its view (static pose,
    arm_joint_1 at -80 deg): what the camera sees where the arm is not."""
    away = copy.deepcopy(scenario)
    away.trajectory.kind = "static"
    away.trajectory.home_deg = {"arm_joint_1": -80.0}
    return simulate_and_record(away, duration_s=0.2, image_stride=away.camera.render_stride,
                               validate=False).depth_images_m


def new_tracker(model, camera) -> Tracker:
    return Tracker(model, camera, fast_params())


def snapshot(tracker: Tracker) -> Tracker:
    """A copy of ``tracker``'s state that shares its model and image processor (whose
    random numbers are drawn per image from the seed and the sequence number)."""
    shared = (tracker.model, tracker.readout, tracker.images)
    return copy.deepcopy(tracker, memo={id(x): x for x in shared})


def replay(tracker, run, start_s=-np.inf, until_s=np.inf, stamps=None):
    """Feeds ``run``'s readings whose true time is in [start_s, until_s] to ``tracker``,
    reading ``k`` stamped ``stamps[k]`` (default: its true time), and each image in
    arrival order before the first reading after it (the images fed for the readings
    before ``start_s`` were fed by the replay that ended there). Returns the truth times
    in that span and the hand's translation error there (mm; NaN where the estimate is
    not finite or before the first reading). Images that raise ValueError are skipped,
    as ``drake-tracker track`` does."""
    stamps = run.reading_times_s if stamps is None else stamps
    first = int(np.searchsorted(run.reading_times_s, start_s))
    before = run.reading_times_s[first - 1] if first > 0 else -np.inf
    order = np.argsort(run.image_arrival_times_s, kind="stable")
    i = int(np.searchsorted(run.image_arrival_times_s[order], before, side="left"))
    s = int(np.searchsorted(run.truth_times_s, before, side="left"))
    span = slice(s, int(np.searchsorted(run.truth_times_s, until_s, side="right")))
    times = run.truth_times_s[span]
    X = np.full((len(times), 4, 4), np.nan)
    for k in range(first, len(run.reading_times_s)):
        t = run.reading_times_s[k]
        if t > until_s:
            break
        while i < len(order) and run.image_arrival_times_s[order[i]] < t:
            j = order[i]
            try:
                tracker.add_image(DepthFrame(float(run.image_capture_times_s[j]),
                                             float(run.image_arrival_times_s[j]),
                                             run.depth_images_m[j], int(j)))
            except ValueError:
                pass
            i += 1
        while s < span.stop and run.truth_times_s[s] < t:
            if tracker.started:
                X[s - span.start] = tracker.estimate().X_CE
            s += 1
        tracker.add_reading(float(stamps[k]), run.readings_rad[k])
    if tracker.started:  # the samples after the last reading fed
        X[s - span.start:] = tracker.estimate().X_CE
    return times, pose_errors(X, run.truth_X_CE[span])[0]


@pytest.fixture(scope="module")
def clean(apollo, recorded):
    """The clean replay's errors, and a snapshot of its tracker at ``FAULT_START_S``."""
    tracker = new_tracker(apollo, recorded.camera_intrinsics)
    head_times, head = replay(tracker, recorded, until_s=FAULT_START_S - 1e-9)
    at_fault_start = snapshot(tracker)
    times, tail = replay(tracker, recorded, start_s=FAULT_START_S)
    return np.concatenate([head_times, times]), np.concatenate([head, tail]), at_fault_start


# ----------------------------------------------------------------- the faults
def images_in(run, start_s, duration_s):
    return (run.image_capture_times_s >= start_s) & (
        run.image_capture_times_s < start_s + duration_s)


def readings_in(run, start_s, duration_s):
    return (run.reading_times_s >= start_s) & (run.reading_times_s < start_s + duration_s)


def with_images(run, mask, images):
    depth = run.depth_images_m.copy()
    depth[mask] = images
    return replace(run, depth_images_m=depth)


def no_images(run, background):
    keep = ~images_in(run, FAULT_START_S, IMAGE_OUTAGE_S)
    return replace(run, image_capture_times_s=run.image_capture_times_s[keep],
                   image_arrival_times_s=run.image_arrival_times_s[keep],
                   depth_images_m=run.depth_images_m[keep]), None, IMAGE_OUTAGE_S


def arm_out_of_view(run, background):
    mask = images_in(run, FAULT_START_S, 1.0)
    cycled = background[np.arange(mask.sum()) % len(background)]
    return with_images(run, mask, cycled), None, 1.0


def full_occlusion(run, background):
    """A plane 0.3 m in front of the camera fills the view (the arm is 0.4-1 m away)."""
    return with_images(run, images_in(run, FAULT_START_S, 2.0), 0.3), None, 2.0


def no_readings(run, background):
    keep = ~readings_in(run, FAULT_START_S, 1.0)
    return replace(run, reading_times_s=run.reading_times_s[keep],
                   readings_rad=run.readings_rad[keep]), None, 1.0


def nan_burst(run, background):
    readings = run.readings_rad.copy()
    readings[readings_in(run, FAULT_START_S, 0.5)] = np.nan
    return replace(run, readings_rad=readings), None, 0.5


def glitched_stamp(run, background):
    stamps = run.reading_times_s.copy()
    stamps[np.searchsorted(stamps, FAULT_START_S)] += 1000.0
    return run, stamps, 0.0


def clock_step(step_s):
    def fault(run, background):
        stamps = run.reading_times_s.copy()
        stamps[stamps >= FAULT_START_S] += step_s
        return run, stamps, 0.0
    fault.__name__ = f"encoder_clock_step_{step_s:+g}s"
    return fault


def images_out_of_order(run, background):
    """For 1 s, every third image arrives after the two that follow it."""
    arrivals = run.image_arrival_times_s.copy()
    late = np.flatnonzero(images_in(run, FAULT_START_S, 1.0))[::3]
    arrivals[late] = arrivals[late + 2] + 1e-3
    return replace(run, image_arrival_times_s=arrivals), None, 1.0


def burst_after_stall(run, background):
    """The camera link stalls, then delivers 10 images at once."""
    arrivals = run.image_arrival_times_s.copy()
    burst = np.flatnonzero(images_in(run, FAULT_START_S, 1.0))[:10]
    arrivals[burst] = arrivals[burst[-1]]
    duration = run.image_capture_times_s[burst[-1]] - FAULT_START_S
    return replace(run, image_arrival_times_s=arrivals), None, duration


def bad_images(kind):
    def fault(run, background):
        mask = images_in(run, FAULT_START_S, 1.0)
        images = {"all NaN": np.nan, "all zero": 0.0,
                  "millimetres": run.depth_images_m[mask] * 1000.0}[kind]
        return with_images(run, mask, images), None, 1.0
    fault.__name__ = f"{kind.replace(' ', '_')}_images"
    return fault


def encoders_alone_mm(model, run, times):
    """The encoders-only error (mm) at ``times`` on ``run``'s readings, each held until
    the next finite one (forward kinematics with the nominal camera)."""
    finite = np.all(np.isfinite(run.readings_rad), axis=1)
    held = replace(run, reading_times_s=run.reading_times_s[finite],
                   readings_rad=run.readings_rad[finite])
    error = pose_errors(encoders_only_X_CE(held, model), run.truth_X_CE)[0]
    return error[np.searchsorted(run.truth_times_s, times)]


FAULTS = [no_images, arm_out_of_view, full_occlusion,
          no_readings, nan_burst, glitched_stamp, clock_step(-1.0), clock_step(+1.0),
          clock_step(+200.0), images_out_of_order, burst_after_stall, bad_images("all NaN"),
          bad_images("all zero"), bad_images("millimetres")]


def fault_name(fault) -> str:
    return fault.values[0].__name__ if hasattr(fault, "values") else fault.__name__


@pytest.mark.parametrize("fault", FAULTS, ids=[fault_name(f) for f in FAULTS])
def test_the_tracker_survives_the_fault_and_recovers(apollo, recorded, background, clean,
                                                    fault, caplog):
    run, stamps, duration_s = fault(recorded, background)
    end_s = FAULT_START_S + duration_s
    clean_times, clean_error, at_fault_start = clean
    tracker = snapshot(at_fault_start)
    with caplog.at_level(logging.WARNING):
        times, error = replay(tracker, run, FAULT_START_S, end_s + 4.0 + 1e-6, stamps)
    assert times[0] <= FAULT_START_S and times[-1] >= end_s + 3.99
    assert np.all(np.isfinite(error)), "the estimate was not finite"
    print(f"{fault.__name__}: max {np.max(error):.1f} mm from the fault's start on; "
          f"{tracker.num_images_applied} images applied")
    if fault.__name__ in BOUND_MM:
        encoders = encoders_alone_mm(apollo, run, times)
        assert np.all(error < encoders), "worse than the encoders alone"
    assert np.max(error) < BOUND_MM.get(fault.__name__, LOSSLESS_MM)
    if fault.__name__ == "arm_out_of_view":  # skipped, and said so
        assert "no arm where one must be" in caplog.text
    if fault.__name__ == "encoder_clock_step_+1s":  # told from an encoder gap
        assert "re-aligned" in caplog.text
    window = (times >= end_s + 3.0) & (times <= end_s + 4.0)
    clean_window = (clean_times >= end_s + 3.0) & (clean_times <= end_s + 4.0)
    recovered, reference = np.median(error[window]), np.median(clean_error[clean_window])
    print(f"  median over [end + 3 s, end + 4 s]: {recovered:.2f} mm, clean {reference:.2f}")
    assert recovered <= reference + RECOVERY_SLACK_MM


def test_a_snapshot_continues_exactly_like_its_original(apollo, recorded, clean):
    """The matrix's premise: a faulted replay from the clean snapshot at the fault's start
    is the replay from the start with that fault."""
    clean_times, clean_error, at_fault_start = clean
    times, continued = replay(snapshot(at_fault_start), recorded, FAULT_START_S,
                              FAULT_START_S + 0.5)
    assert len(times) == 51
    np.testing.assert_array_equal(continued,
                                  clean_error[np.searchsorted(clean_times, times)])
