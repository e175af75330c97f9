"""Each camera's frame against the truth (``evaluation/camera_frames.py``): known offset
errors give known errors, checked against Drake's kinematics."""

import numpy as np
import pytest

from drake_tracker.core.render.configurations import default_view_configuration
from drake_tracker.evaluation.camera_frames import (
    camera_frame_errors,
    camera_summary,
    true_positions,
)
from drake_tracker.io.synthetic import synthetic_run
from drake_tracker.robot.config import CameraMount, FrameOffset
from drake_tracker.robot.model import build_tracker_model, robot_preset


@pytest.fixture(scope="module")
def two_cameras():
    config = robot_preset("apollo")
    config.added_frames = {"post_nominal": FrameOffset(
        parent="torso", xyz_m=[1.2, -1.45, 1.45], rpy_deg=[-114.44, 0.0, 38.29])}
    config.cameras = [CameraMount("camera", "camera_optical"),
                      CameraMount("post", "post_nominal")]
    return build_tracker_model(config)


def _hand_in(model, q, camera):
    """The hand in ``camera``'s frame at ``q``, from Drake directly."""
    plant = model.plant
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, q)
    return plant.CalcRelativeTransform(context, model.camera(camera).frame,
                                       model.end_effector_frame).GetAsMatrix4()


def test_a_camera_offset_error_is_that_cameras_alone(two_cameras):
    model = two_cameras
    truth = np.array(default_view_configuration(model), float)
    truth[model.camera_joint_indices("camera")] = [0.01, -0.02, 0.005, 0.02, -0.01, 0.03]
    truth[model.camera_joint_indices("post")] = [-0.015, 0.01, 0.02, -0.03, 0.02, 0.01]
    estimate = truth.copy()
    estimate[model.camera_joint_indices("post")[0]] += 0.005  # post x: 5 mm
    estimate[model.camera_joint_indices("camera")[5]] += 0.01  # head rz: 0.01 rad
    positions = np.stack([estimate, np.full_like(estimate, np.nan)])
    errors = camera_frame_errors(model, positions, np.stack([truth, truth]))
    post, head = errors["post"], errors["camera"]
    # the post camera moved 5 mm along its nominal x: its pose and the hand in its frame
    # move by 5 mm, nothing turns
    for key, value in (("offset_mm", 5.0), ("offset_deg", 0.0), ("pose_mm", 5.0),
                       ("pose_deg", 0.0), ("hand_mm", 5.0), ("hand_deg", 0.0)):
        assert post[key][0] == pytest.approx(value, abs=1e-6), key
    # the head camera turned 0.01 rad about its own z: the hand in its frame turns about
    # that axis, by 2 sin(0.005) times its distance from the axis
    p = _hand_in(model, truth, "camera")[:3, 3]
    turned = 1000.0 * 2.0 * np.sin(0.005) * np.hypot(p[0], p[1])
    for key, value in (("offset_mm", 0.0), ("offset_deg", np.degrees(0.01)),
                       ("pose_mm", 0.0), ("pose_deg", np.degrees(0.01)),
                       ("hand_mm", turned), ("hand_deg", np.degrees(0.01))):
        assert head[key][0] == pytest.approx(value, abs=1e-6), key
    # a sample before the tracker started has no estimate
    assert all(np.isnan(e[key][1]) for e in errors.values() for key in e)


def test_the_truth_takes_each_cameras_offset_by_name(two_cameras):
    model = build_tracker_model(robot_preset("apollo"))
    run = synthetic_run(model, duration_s=0.2, seed=3)
    index = np.array([0, len(run.truth_times_s) - 1])
    q = true_positions(run, model, index)
    assert np.array_equal(q[:, model.robot_joint_indices], run.truth_positions_rad[index])
    assert np.array_equal(q[:, model.camera_joint_indices("camera")],
                          run.truth_camera_offset[index])
    # one camera is the model's first, whatever the run calls it, as a replay takes it
    from dataclasses import replace

    renamed = true_positions(replace(run, camera_name="wrist"), model, index)
    assert np.array_equal(renamed, q)
    with pytest.raises(ValueError, match=r"no truth for the model's cameras \['post'\]"):
        true_positions(run, two_cameras, index)


def test_the_summary_takes_the_median_over_seeds_of_each_seeds_median():
    rows = []
    for seed, values in enumerate(([1.0, 2.0, 3.0], [10.0, 20.0, 30.0], [4.0, 5.0, 6.0])):
        for t, v in enumerate(values):
            rows.append({"sequence": "s", "bias": "b", "method": "full_fusion", "seed": seed,
                         "time_s": float(t), "camera": "post", "hand_mm": v,
                         "hand_deg": 0.1, "pose_mm": v, "pose_deg": 0.2,
                         "offset_mm": v, "offset_deg": 0.3})
    table = camera_summary(rows, settle_s=2.0)
    (line,) = [row for row in table.splitlines() if row.startswith("| s |")]
    # per-seed medians 2, 20, 5 (p75 2.5, 25, 5.5); the offsets from 2 s: 3, 30, 6
    assert "| 3 | 5.0 / 5.5 (20.0) | 0.10 | 5.0, 0.20 | 6.0 (30.0), 0.30 (0.30) |" in line


def test_a_camera_the_run_never_recorded_leaves_the_run_evaluated_without_camera_errors():
    from dataclasses import replace

    from drake_tracker.evaluation import evaluate_run

    # a one-camera run of a robot whose configuration declares a second camera
    run = synthetic_run(build_tracker_model(robot_preset("apollo")), duration_s=0.3, seed=2)
    run = replace(run, robot_config_yaml=(
        "{model_file: apollo.sdf, end_effector_frame: end_effector, added_frames: "
        "{post_nominal: {parent: torso, xyz_m: [1.2, -1.45, 1.45], rpy_deg: [-114.44, 0.0, "
        "38.29]}}, cameras: [{name: camera, frame: camera_optical}, "
        "{name: post, frame: post_nominal}]}"))
    with pytest.warns(UserWarning, match=r"no truth for the model's cameras \['post'\]"):
        errors = evaluate_run(run, ("full_fusion",), min_image_interval_s=0.0)
    assert "cameras" not in errors["full_fusion"]
    assert np.isfinite(errors["full_fusion"]["translation_mm"]).any()


def test_a_run_shorter_than_the_settling_time_reads_n_a_not_nan():
    rows = [{"sequence": "s", "bias": "none", "method": "full_fusion", "seed": 0,
             "time_s": t, "camera": "post", "hand_mm": 1.0, "hand_deg": 0.1,
             "pose_mm": 2.0, "pose_deg": 0.2, "offset_mm": 3.0, "offset_deg": 0.3}
            for t in (0.0, 0.5, 1.0)]
    table = camera_summary(rows, settle_s=5.0)
    assert "nan" not in table
    assert "| 1 | 1.0 / 1.0 (1.0) | 0.10 | 2.0, 0.20 | n/a (n/a), n/a (n/a) |" in table
    assert "n/a: no sample from 5 s on" in table
    assert "n/a" not in camera_summary(rows, settle_s=0.5)
