"""Issue 14's remaining input findings: parameter and scenario files whose bad fields
gave raw Python errors or failed later, an empty parameter file, a corrupt recording,
and 16-bit millimetre depth images in the offline tracker."""

import dataclasses

import numpy as np
import pytest
from fast_params import small_params

from drake_tracker.core.sensors.depth_frames import DepthFrame, depth_to_metres
from drake_tracker.io.recording import RecordedRun
from drake_tracker.io.synthetic import synthetic_run
from drake_tracker.params.loading import load_tracker_params, tracker_params_to_yaml
from drake_tracker.params.tracker_params import TrackerParams
from drake_tracker.sim.scenario.load import load_scenario
from drake_tracker.tracker import Tracker


def write(tmp_path, name: str, text: str):
    path = tmp_path / name
    path.write_text(text)
    return path


@pytest.mark.parametrize("field", ["max_depth_m", "occluder_rate_per_m",
                                   "depth_noise_std_m"])
def test_an_infinite_likelihood_field_is_rejected_at_load_by_name(tmp_path, field):
    """These loaded, then failed at the first image."""
    path = write(tmp_path, "p.yaml", f"image:\n  likelihood:\n    {field}: .inf\n")
    with pytest.raises(ValueError, match=rf"p\.yaml: image\.likelihood\.{field} = inf"):
        load_tracker_params(path)


def test_an_empty_parameter_file_gives_the_defaults(tmp_path):
    for text in ("", "# only a comment\n"):
        loaded = load_tracker_params(write(tmp_path, "empty.yaml", text))
        assert tracker_params_to_yaml(loaded) == tracker_params_to_yaml(TrackerParams())


@pytest.mark.parametrize("loader, text, message", [
    (load_tracker_params, "image:\n  annealing_betas: 0.5\n",
     "image.annealing_betas: 0.5 (expected a list)"),
    (load_tracker_params, "health:\n  lost_after_images: 3\n",
     "health.lost_after_images: replaced by health.images_in_a_row"),
    (load_tracker_params, "image:\n  estimate_occlusion: false\n",
     "image.estimate_occlusion: removed"),
    (load_tracker_params, "health:\n  no_arm_see_through: 0.9\n",
     "health.no_arm_see_through: removed"),
    (load_tracker_params, "kalman:\n  robot_joints:\n    match_bias_noise_to_images: true\n",
     "kalman.robot_joints.match_bias_noise_to_images: removed"),
    (load_tracker_params,
     "kalman:\n  overrides:\n    arm_joint_1:\n      match_bias_noise_to_images: true\n",
     "kalman.overrides.arm_joint_1.match_bias_noise_to_images: removed"),
    (load_tracker_params, "health:\n  challenger_bias_sigmas: 2.25\n",
     "health.challenger_bias_sigmas: removed"),
    (load_tracker_params, "health:\n  challenger_images: 20\n",
     "health.challenger_images: removed"),
    (load_tracker_params, "health:\n  second_opinion_agreement: 0.5\n",
     "health.second_opinion_agreement: removed: an image is surprising when more"),
    (load_tracker_params, "health:\n  misplaced_fraction: 0.5\n",
     "health.misplaced_fraction: removed: an estimate is misplaced when it renders"),
    (load_scenario, "duration_s: long\n", "duration_s: 'long' (expected a number)"),
    (load_scenario, "preset: 3\n", "preset: 3 (expected a preset name"),
    (load_scenario, "camera:\n  rate_hz: [30]\n", "camera.rate_hz: [30] (expected a number)"),
    (load_scenario, "duration_s: -1.0\n", "Scenario.duration_s = -1.0"),
])
def test_a_bad_field_is_named_with_its_file(tmp_path, loader, text, message):
    """These gave raw Python errors naming no field ("'float' object is not iterable",
    "could not convert string to float", "'int' object has no attribute 'partition'")."""
    path = write(tmp_path, "bad.yaml", text)
    with pytest.raises(ValueError) as err:
        loader(path)
    assert str(err.value).startswith(f"{path}: ") and message in str(err.value)


def test_the_command_line_names_a_bad_file_once(tmp_path):
    """The loaders' errors begin with the path, and the command line named it again."""
    from drake_tracker.cli.args import UsageError, load_params_arg, resolve_scenario

    params = write(tmp_path, "bad.yaml", "health:\n  no_arm_see_through: 0.9\n")
    scenario = write(tmp_path, "scene.yaml", "duration_s: long\n")
    for call, path, message in ((load_params_arg, params, "no_arm_see_through: removed"),
                                (resolve_scenario, scenario, "(expected a number)")):
        with pytest.raises(UsageError) as err:
            call(str(path))
        assert str(err.value).count(str(path)) == 1 and message in str(err.value)


def test_an_empty_scenario_file_gives_the_default_scenario(tmp_path):
    scenario = load_scenario(write(tmp_path, "mine.yaml", ""))
    assert scenario.name == "mine" and scenario.duration_s > 0


@pytest.fixture(scope="module")
def run(apollo):
    return synthetic_run(apollo, duration_s=0.3, encoder_rate_hz=200.0, seed=5)


def test_a_corrupt_recording_is_a_clear_error_naming_the_file(tmp_path, run):
    good = run.save(tmp_path / "good.npz")
    truncated = tmp_path / "truncated.npz"
    truncated.write_bytes(good.read_bytes()[:3000])
    text = write(tmp_path, "text.npz", "not an archive")
    empty = tmp_path / "keys.npz"
    np.savez(empty, format_version=np.array(1))
    for path in (truncated, text, empty):
        with pytest.raises(ValueError) as err:
            RecordedRun.load(path)
        assert str(err.value).startswith(f"{path}: not a") and "pickle" not in str(err.value)
    assert len(RecordedRun.load(good).reading_times_s) == len(run.reading_times_s)


@pytest.mark.parametrize("glitch", [1000.0, np.nan, "repeat"])
def test_a_recording_with_a_glitched_reading_stamp_names_the_reading(run, glitch):
    stamps = run.reading_times_s.copy()
    stamps[7] = stamps[6] if glitch == "repeat" else stamps[7] + glitch
    k = 8 if glitch == 1000.0 else 7  # a glitch forward shows at the next reading
    with pytest.raises(ValueError, match=rf"strictly increasing and finite: reading {k} ") as err:
        dataclasses.replace(run, reading_times_s=stamps)
    assert f"stamped {float(stamps[k])!r} s after {float(stamps[k - 1])!r} s" in str(err.value)


def test_sixteen_bit_millimetre_images_are_read_as_metres(apollo, run):
    """The Diagram's input took ImageDepth16U; the offline tracker raised on uint16."""
    millimetres = np.round(run.depth_images_m[3] * 1000.0).astype(np.uint16)
    millimetres[:5, :] = 0  # no return
    millimetres[-3:, :] = 65535  # too far
    metres = depth_to_metres(millimetres, "16U_mm")
    assert np.isnan(metres[:5]).all() and np.isnan(metres[-3:]).all()
    estimates = []
    for image in (metres, millimetres):
        tracker = Tracker(apollo, run.camera_intrinsics, small_params())
        for t, reading in zip(run.reading_times_s, run.readings_rad, strict=True):
            tracker.add_reading(t, reading)
        assert tracker.add_image(DepthFrame(0.1, 0.15, image, 3))
        estimates.append(tracker.estimate().positions)
    np.testing.assert_array_equal(estimates[1], estimates[0])


@pytest.mark.parametrize("loader", [load_tracker_params, load_scenario])
def test_a_yaml_syntax_error_names_the_file(tmp_path, loader):
    """It raised yaml's ParserError, naming no file."""
    path = write(tmp_path, "broken.yaml", "image: [\n")
    with pytest.raises(ValueError, match=rf"^{path}: "):
        loader(path)


def test_an_absurd_reading_is_skipped_like_a_non_finite_one(apollo, run, caplog):
    """A finite reading of 1e300 rad was accepted, and the next image crashed the tracker
    (the CPF's proposal overflowed); a stamp that is not a number raised a TypeError."""
    tracker = Tracker(apollo, run.camera_intrinsics, small_params())
    k = len(run.reading_times_s) // 2
    for j in range(len(run.reading_times_s)):
        value = np.full_like(run.readings_rad[j], 1e300) if j == k else run.readings_rad[j]
        with caplog.at_level("WARNING"):
            tracker.add_reading(run.reading_times_s[j], value)
    assert f"{run.reading_times_s[k]:.4f} s is not finite" in caplog.text
    assert tracker.add_image(DepthFrame(0.2, 0.25, run.depth_images_m[6], 6))
    assert np.all(np.isfinite(tracker.estimate().positions))
    with pytest.raises(ValueError, match="time stamp 'x' is not a number"):
        tracker.add_reading("x", run.readings_rad[0])
    with pytest.raises(ValueError, match="not numeric"):
        tracker.add_reading(1.0, ["a"] * len(run.joint_names))


def test_images_without_an_arrival_time_are_skipped_warned_and_counted(apollo, run, caplog):
    """Issue 44's probe: NaN arrival stamps passed the format check and replay_run applied
    fewer images with no warning, counting none as skipped. Now each is warned about and
    counted, offline and by the Diagram's source, and the other images are all played."""
    from dataclasses import replace

    from drake_tracker.io.replay import replay_run
    from drake_tracker.systems.recorded_run_source import RecordedRunSource

    arrivals = run.image_arrival_times_s.copy()
    lost = [2, 5, 6]
    arrivals[lost] = np.nan
    faulty = replace(run, image_arrival_times_s=arrivals)
    p = TrackerParams()
    p.image.num_particles, p.image.min_image_interval_s = 20, 0.0
    clean = replay_run(run, p, apollo)
    with caplog.at_level("WARNING"):
        result = replay_run(faulty, p, apollo)
    text = caplog.text
    # Rate-limited: the first of the kind is logged (then the 10th, 100th, ...).
    assert "image 2 skipped: its arrival stamp is nan, not a time" in text
    assert result.num_images_skipped == clean.num_images_skipped + len(lost)
    assert result.num_images_applied + result.num_images_skipped == len(arrivals)
    caplog.clear()
    with caplog.at_level("WARNING"):
        source = RecordedRunSource(faulty)
    assert source.num_unplayable_images == len(lost) and "[2, 5, 6]" in caplog.text
