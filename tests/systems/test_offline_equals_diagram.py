"""One property over every mechanism of the per-image step: the offline ``Tracker`` and
the Diagram (``AddTracker``) give the same estimates from the same data, bit for bit
(1e-9) wherever no image is in flight, and apply the same images.

Each case forces one mechanism: plain tracking on two robots, the update on the worker
thread, the time-stamp policy (a glitch, a clock step, a counter restart, an image out
of order; a NaN burst; a glitched first stamp; a clock step of both streams; an
encoder clock step forward), a restart, a second opinion, a
challenger, and images that show no arm."""

import logging
from dataclasses import dataclass, field, replace

import numpy as np
import pytest
from fast_params import small_params
from offline_vs_diagram import H, assert_same_when_settled, feed, simulate
from switches import switch_second_opinion_off

from drake_tracker.core import image_processor
from drake_tracker.core.calibration.calibration_params import SelfCalibrationParams
from drake_tracker.core.robustness import health, second_opinion
from drake_tracker.core.robustness.health import agreeing_pixels, confirms_more
from drake_tracker.io.synthetic import synthetic_run
from drake_tracker.robot.model import build_tracker_model, robot_preset
from drake_tracker.tracker import Tracker


@dataclass
class Case:
    """A run, its parameters and faults, and what the offline tracker must show."""

    robot: str = "apollo"
    duration_s: float = 0.5
    seed: int = 7
    bias_deg: float = 3.0
    #: (run, params) -> (run, stamps, sequences) with the faults applied.
    faults: object = None
    tune: object = None
    #: (monkeypatch) -> None: a rule of the decision changed for the case.
    patch: object = None
    latency_s: float = 0.0
    #: Compare from this reading on (before it the estimates differ by design).
    first: int = 0
    #: Logged by the offline tracker, or by the Diagram.
    offline_log: tuple = ()
    diagram_log: tuple = ()
    min_restarts: int = 0
    all_applied: bool = False
    some_skipped: bool = False
    extra: dict = field(default_factory=dict)


def _plain(p):
    p.image.num_particles, p.image.seed = 40, 4


def _latency(p):
    _plain(p)
    p.image.update_latency_s = 0.01  # shorter than the 33 ms between images


def _stamp_faults(run):
    stamps = run.reading_times_s.copy()
    stamps[20] += 1000.0  # a glitch
    stamps[60:] -= 1.0  # the encoders' clock steps back
    sequences = np.arange(len(run.image_capture_times_s))
    sequences[8:] -= 8  # the camera's counter restarts at image 8
    arrivals = run.image_arrival_times_s.copy()
    arrivals[4] = arrivals[5] + 2 * H  # image 4 arrives after image 5
    return replace(run, image_arrival_times_s=arrivals), stamps, sequences


def _nan_burst(run):
    burst = run.readings_rad.copy()
    burst[(run.reading_times_s >= 0.15) & (run.reading_times_s < 0.3)] = np.nan
    return replace(run, readings_rad=burst), None, None


def _one_joint_nan_burst(run):
    burst = run.readings_rad.copy()
    burst[(run.reading_times_s >= 0.15) & (run.reading_times_s < 0.3), 1] = np.nan
    return replace(run, readings_rad=burst), None, None


def _glitched_first_stamp(run):
    stamps = run.reading_times_s.copy()
    stamps[0] = 1e6
    return run, stamps, None


def _shared_clock_step(run):
    stamps = run.reading_times_s - 1.0 * (run.reading_times_s >= 0.2)
    captures = run.image_capture_times_s - 1.0 * (run.image_capture_times_s >= 0.2)
    return replace(run, image_capture_times_s=captures), stamps, None


def _encoder_step_forward(run):
    return run, run.reading_times_s + 0.2 * (run.reading_times_s >= 0.22), None


def _no_arm(run):
    images = run.depth_images_m.copy()
    gone = (run.image_capture_times_s >= 0.9) & (run.image_capture_times_s < 1.2)
    noise = np.random.default_rng(11).normal(0.0, 0.002, images[gone].shape)
    images[gone] = (2.5 + noise).astype(images.dtype)
    return replace(run, depth_images_m=images), None, None


def _restart(p):
    p.health.max_unconfirmed_s = 1e-6


def _misplaced_at_99_percent(monkeypatch):
    """An estimate that renders fewer pixels than 99 % of the encoders' arm counts as
    misplaced (not half), so that a 4 deg bias restarts."""
    def misplaced(estimate, encoders, params, health=None):
        return (encoders.robot_pixels >= params.min_robot_pixels
                and estimate.robot_pixels < 0.99 * encoders.robot_pixels
                and not confirms_more(estimate, encoders, params))
    monkeypatch.setattr(image_processor, "is_misplaced", misplaced)


def _nearer(run):
    """Every depth 10 cm nearer: the image confirms neither the estimate's arm nor the
    encoders' (both hidden), so a misplaced estimate restarts (``is_misplaced``)."""
    return replace(run, depth_images_m=run.depth_images_m - np.float32(0.1)), None, None


def _second_opinion(p):
    p.health.second_opinion_margin_nats_per_pixel = 0.0
    p.image.num_particles = 5


def _any_disagreement_surprises(monkeypatch):
    """An image whose unhidden arm disagrees anywhere contradicts the estimate (not
    where most of it disagrees), so that a 0.5 deg bias asks a second opinion."""
    def contradicts(image, params):
        visible = image.visible_robot_pixels
        return visible >= params.min_robot_pixels and agreeing_pixels(image) < visible
    monkeypatch.setattr(health, "contradicts", contradicts)


def _challenger(p):
    p.health.second_opinion_margin_nats_per_pixel = 0.0
    p.image.num_particles = 5


def _challenger_alone(monkeypatch):
    """A challenger at a 0.5 deg bias: its threshold made tiny, the second opinion off."""
    monkeypatch.setattr(second_opinion, "IMPLAUSIBLE_BIAS_SIGMAS", 0.01)
    switch_second_opinion_off(monkeypatch)


CASES = {
    "plain": Case(duration_s=0.6, seed=4, tune=_plain),
    "another robot": Case(robot="arm6", duration_s=0.6, seed=4, tune=_plain),
    "update on the worker thread": Case(duration_s=0.6, seed=4, tune=_latency,
                                        latency_s=0.01),
    "glitch, clock step, counter restart, out of order": Case(
        faults=_stamp_faults, all_applied=True,
        diagram_log=("restarted", "far in the future", "re-anchored")),
    "NaN burst": Case(faults=_nan_burst, some_skipped=True,
                      diagram_log=("not finite", "gap of the joint readings")),
    "one joint's NaN burst": Case(faults=_one_joint_nan_burst, all_applied=True,
                                  diagram_log=("no usable value",)),
    "glitched first stamp": Case(faults=_glitched_first_stamp, first=10,
                                 offline_log=("restarted at",)),
    "a clock step of both streams": Case(faults=_shared_clock_step, some_skipped=True,
                                         offline_log=("re-aligned",)),
    "an encoder clock step forward": Case(faults=_encoder_step_forward, some_skipped=True,
                                          offline_log=("in a gap of the readings at the "
                                                       "same lag",)),
    "restart": Case(bias_deg=4.0, tune=_restart, patch=_misplaced_at_99_percent,
                    faults=_nearer, min_restarts=1,
                    offline_log=("while the encoders put it in view",)),
    "second opinion": Case(bias_deg=0.5, tune=_second_opinion,
                           patch=_any_disagreement_surprises, min_restarts=1,
                           offline_log=("search from the encoders' arm explains it better",)),
    "challenger": Case(bias_deg=0.5, tune=_challenger, patch=_challenger_alone,
                       min_restarts=1,
                       offline_log=("a challenger searched from the encoders' arm",)),
    "images without the arm": Case(duration_s=1.6, seed=3, bias_deg=2.0, faults=_no_arm,
                                   some_skipped=True, offline_log=("no arm where one must be",)),
}


@pytest.fixture(scope="module")
def arm6():
    return build_tracker_model(robot_preset("arm6"))


@pytest.mark.parametrize("name", list(CASES))
def test_offline_tracker_and_diagram_give_the_same_estimates(name, request, caplog,
                                                            monkeypatch):
    case = CASES[name]
    if case.patch is not None:
        case.patch(monkeypatch)
    model = request.getfixturevalue(case.robot)
    run = synthetic_run(model, duration_s=case.duration_s, encoder_rate_hz=1.0 / H,
                        seed=case.seed, bias_rad=np.radians(case.bias_deg))
    p = small_params()
    if case.tune is not None:
        case.tune(p)
    run, stamps, sequences = case.faults(run) if case.faults else (run, None, None)
    tracker = Tracker(model, run.camera_intrinsics, p)
    caplog.clear()
    with caplog.at_level(logging.WARNING):
        offline, applied = feed(tracker, run, stamps=stamps, sequences=sequences)
    for message in case.offline_log:
        assert message in caplog.text, message
    assert tracker.health.restarts >= case.min_restarts
    assert sum(applied.values()) > 5  # the images did their work
    if case.all_applied:
        assert all(applied.values())
    if case.some_skipped:
        assert not all(applied.values())
    caplog.clear()
    with caplog.at_level(logging.WARNING):
        diagram, images_applied = simulate(model, run, p, stamps, sequences)
    for message in case.diagram_log:
        assert message in caplog.text, message
    assert images_applied == sum(applied.values())
    assert_same_when_settled(run, diagram, offline, case.first, case.latency_s)


@pytest.fixture(scope="module")
def two_camera_run():
    """2 s of the two-camera preset with lasting occlusion: the second camera sees the
    arm when the first does not (recorded by the simulated world)."""
    from drake_tracker.sim.record import simulate_and_record
    from drake_tracker.sim.scenario.load import load_scenario

    return simulate_and_record(load_scenario("occlusion-lasting-2cam/constant"),
                               duration_s=2.0)


#: Calibrated, held offsets of the two cameras (``camera_offsets``): both shells read them.
CALIBRATED = {"camera": [0.02, -0.015, 0.018, 0.046, -0.026, 0.017],
              "post_camera": [-0.015, 0.02, -0.01, -0.026, 0.017, 0.035]}


@pytest.mark.parametrize("latency_s, calibrated", [(0.0, ""), (0.01, ""), (0.0, "given"),
                                                   (0.0, "online")])
def test_two_cameras_give_the_same_estimates_offline_and_in_the_diagram(two_camera_run,
                                                                        latency_s, calibrated):
    """The same recorded two-camera data through the offline ``Tracker`` (images named
    by camera) and through ``AddTracker(cameras=...)``: the same joint estimates and the
    same offset of each camera wherever no image is in flight, and the same images
    applied, each camera's through its own update. With the update on the worker
    thread, an update of one camera still in flight when the other camera's image comes
    is applied first, as the offline tracker applies it. Calibrated: the offsets given
    (``camera_offsets``) or fitted by the tracker itself on its first half second in
    which both cameras see the arm (``camera_calibration``), held in both shells."""
    from offline_vs_diagram import feed_cameras, simulate_cameras

    from drake_tracker.io.replay import model_for_run

    run = two_camera_run
    model = model_for_run(run)
    assert run.camera_names == model.camera_names == ["camera", "post_camera"]
    h = float(np.median(np.diff(run.reading_times_s)))
    times = run.reading_times_s + 0.6 * h
    p = small_params()
    p.image.seed, p.image.update_latency_s = 5, latency_s
    p.camera_calibration.window_s = 0.0
    if calibrated == "given":
        p.camera_offsets, p.estimate_camera_offset = CALIBRATED, False
    if calibrated == "online":  # a short window and fit: the same one in both shells
        p.camera_calibration = SelfCalibrationParams(window_s=0.5, max_evaluations=480)
    tracker = Tracker(model, params=p, cameras={run.camera_name: run.camera_intrinsics} | {
        c.name: c.intrinsics for c in run.other_cameras})
    offline, applied = feed_cameras(tracker, run, times)
    assert min(applied.values()) > 10  # both cameras' images did their work
    positions, offsets, cpf = simulate_cameras(model, run, p, h, times)
    assert cpf.images_applied + (cpf.in_flight is not None) == sum(applied.values())
    first = next(k for k, e in enumerate(offline) if e is not None)
    arrivals = np.concatenate([run.image_arrival_times_s] + [
        c.arrival_times_s for c in run.other_cameras])
    # A frame that comes at the check of another camera's is taken one check later.
    margin = latency_s + 2 * h
    assert_same_when_settled(run, positions,
                             [None if e is None else e.positions for e in offline],
                             first, margin, h, arrivals)
    for name in model.camera_names:
        assert_same_when_settled(
            run, [o[name] for o in offsets],
            [None if e is None else e.camera_offsets[name] for e in offline],
            first, margin, h, arrivals)
    final = offline[-1].camera_offsets
    if calibrated == "online":
        held = tracker.held
        assert held is not None and cpf.calibration.held is not None
        assert cpf.calibration.held.window_s == held.window_s
        assert cpf.calibration.held.log_likelihood == held.log_likelihood
        np.testing.assert_array_equal(cpf.calibration.held.offsets, held.offsets)
        expected = {name: held.offsets[model.camera_joint_indices(name)]
                    for name in model.camera_names}
    else:
        expected = CALIBRATED
    if calibrated:  # held where the calibration put them, in both shells
        for name in model.camera_names:
            np.testing.assert_allclose(final[name], expected[name], atol=1e-9)
            np.testing.assert_allclose(offsets[-1][name], expected[name], atol=1e-9)
        return
    # Each camera's own offset moved from its prior (0): its images were scored
    # through it.
    assert all(np.any(final[name] != 0.0) for name in model.camera_names)
