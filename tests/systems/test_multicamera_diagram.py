"""Several depth cameras in a Diagram (issue 46): ``AddTracker(cameras=...)`` refuses bad
cameras at construction, names each camera's ports, and a running Diagram or a log
skips an image it cannot use with a rate-limited warning and a count."""

import dataclasses
import logging

import numpy as np
import pytest
from fast_params import small_params
from offline_vs_diagram import feed_cameras, simulate_cameras
from pydrake.systems.framework import DiagramBuilder
from two_cameras import CAMERA, two_camera_config

from drake_tracker.io.recording import CameraImages
from drake_tracker.io.stream import ImageEvent, ReadingEvent, track_stream
from drake_tracker.io.synthetic import synthetic_run
from drake_tracker.robot.model import build_tracker_model
from drake_tracker.systems.add_tracker import AddTracker, TrackerCamera
from drake_tracker.systems.recorded_run_source import RecordedRunSource
from drake_tracker.tracker import Tracker

H = 1.0 / 200.0


@pytest.fixture(scope="module")
def two_cameras():
    return build_tracker_model(two_camera_config())


def _run(apollo, post_capture_shift_s=0.0):
    """A synthetic run whose second camera ``post`` sees the first camera's images,
    subsampled, 10 ms later, its capture stamps shifted by ``post_capture_shift_s``."""
    run = synthetic_run(apollo, duration_s=0.4, camera=CAMERA, seed=2, encoder_rate_hz=1 / H)
    T = len(run.truth_times_s)
    post = CameraImages("post", CAMERA.subsampled(2),
                        run.image_capture_times_s + 0.01 + post_capture_shift_s,
                        run.image_arrival_times_s + 0.01,
                        run.depth_images_m[:, ::2, ::2].copy(), np.zeros((T, 6)))
    return dataclasses.replace(run, other_cameras=[post])


def _add(builder, model, source, cameras):
    return AddTracker(builder, model=model, params=small_params(), encoder_period_s=H,
                      measured_position=source.GetOutputPort("measured_position"),
                      measurement_time=source.GetOutputPort("measurement_time"),
                      cameras=cameras)


def test_bad_cameras_are_refused_when_the_diagram_is_built(apollo, two_cameras):
    run = _run(apollo)
    builder = DiagramBuilder()
    source = builder.AddSystem(RecordedRunSource(run))
    port = source.get_depth_frame_output_port
    with pytest.raises(ValueError, match=r"unknown camera 'side'.*\['camera', 'post'\]"):
        _add(builder, two_cameras, source, [TrackerCamera("side", CAMERA, port("post"))])
    with pytest.raises(ValueError, match="two cameras are named 'post'"):
        _add(builder, two_cameras, source, [TrackerCamera("post", CAMERA, port("post")),
                                            TrackerCamera("post", CAMERA, port("camera"))])
    with pytest.raises(ValueError, match="no camera given"):
        _add(builder, two_cameras, source, [])
    # The one-camera model has no camera 'post': its frame is not in the model.
    with pytest.raises(ValueError, match=r"unknown camera 'post'.*\['camera'\]"):
        _add(builder, apollo, source, [TrackerCamera("post", CAMERA, port("post"))])
    with pytest.raises(TypeError, match="not both"):
        AddTracker(builder, model=two_cameras, camera=CAMERA, depth=port("camera"),
                   encoder_period_s=H, measured_position=source.GetOutputPort(
                       "measured_position"), measurement_time=source.GetOutputPort(
                       "measurement_time"), cameras=[TrackerCamera("post", CAMERA,
                                                                   port("post"))])
    with pytest.raises(ValueError, match="unknown camera 'side'"):
        source.get_depth_frame_output_port("side")


def test_each_camera_has_its_own_named_ports(two_cameras, apollo):
    run = _run(apollo)
    builder = DiagramBuilder()
    source = builder.AddSystem(RecordedRunSource(run))
    tracker = _add(builder, two_cameras, source, [
        TrackerCamera(name, CAMERA if name == "camera" else CAMERA.subsampled(2),
                      source.get_depth_frame_output_port(name))
        for name in ("post", "camera")])
    buffer, cpf, bank = tracker.delay_buffer, tracker.image_update, tracker.kalman_bank
    assert buffer.camera_names == cpf.camera_names == ["camera", "post"]  # the model's order
    assert buffer.get_depth_frame_input_port("post").get_name() == "post_depth_frame"
    assert cpf.get_image_prior_input_port("camera").get_name() == "camera_image_prior"
    assert tracker.camera_offsets["post"].get_name() == "post_camera_offset"
    assert tracker.camera_poses["camera"].get_name() == "camera_X_WC"
    assert tracker.camera_health["post"].get_name() == "post_health"
    with pytest.raises(ValueError, match="name one"):
        buffer.get_depth_frame_input_port()
    # The second camera's update renders through its own estimated frame.
    assert cpf.processors["post"].camera_index == 1 and cpf.processor.camera_index == 0
    np.testing.assert_array_equal(
        bank.GetOutputPort("post_camera_offset").Eval(bank.CreateDefaultContext()),
        np.zeros(6))


def test_a_camera_whose_clock_disagrees_is_warned_and_counted_in_the_diagram(
        apollo, two_cameras, caplog):
    """Camera ``post``'s stamps are 5 s behind its arrivals, the other camera's 0.05 s:
    more than the buffer horizon apart. The Diagram skips its images with a rate-limited
    warning and a count, as the offline tracker does, and applies the other camera's."""
    run = _run(apollo, post_capture_shift_s=-5.0)
    p = small_params()
    tracker = Tracker(two_cameras, params=p, cameras={"camera": CAMERA,
                                                      "post": CAMERA.subsampled(2)})
    times = run.reading_times_s + 0.6 * H
    with caplog.at_level(logging.WARNING):
        _, applied = feed_cameras(tracker, run, times)
    kind = "images whose camera clock disagrees"
    assert applied["post"] == 0 and applied["camera"] > 5
    offline_count = tracker.warnings.counts[kind]
    assert offline_count >= 10
    caplog.clear()
    with caplog.at_level(logging.WARNING):
        _, _, cpf_state, cpf = simulate_cameras(two_cameras, run, p, H, times, system=True)
    assert cpf_state.images_applied == applied["camera"]
    assert cpf.warnings.counts[kind] == offline_count
    logged = [r.getMessage() for r in caplog.records if r.name.endswith("cpf_system")]
    assert len(logged) == 2  # the 1st and the 10th: rate-limited
    assert "(camera 'post') camera 'post''s clock disagrees with camera 'camera''s" \
        in logged[0]
    assert cpf_state.cameras["post"].pacing.last_applied_s == -np.inf


def test_an_image_of_an_unknown_camera_in_a_log_is_warned_and_counted(two_cameras, caplog):
    tracker = Tracker(two_cameras, params=small_params(), cameras={"camera": CAMERA})
    n = len(two_cameras.robot_joint_names)
    image = np.full((CAMERA.height, CAMERA.width), 2.0, np.float32)
    events = [ReadingEvent(0.01 * k, np.zeros(n)) for k in range(20)]
    events += [ImageEvent(0.1, image, k, 0.2 + 0.001 * k, "side") for k in range(12)]
    with caplog.at_level(logging.WARNING):
        counts = track_stream(iter(events), tracker)
    assert counts.source_skipped["unusable images"] == 12
    assert caplog.text.count("unknown camera 'side'") == 2  # the 1st and the 10th


def test_each_cameras_pose_output_is_drakes_kinematics_of_the_belief(two_cameras, apollo):
    """``<name>_X_WC`` and ``<name>_X_CE`` of the bank system, at a belief whose offsets
    are away from 0, equal Drake's ``CalcRelativeTransform`` from the world to that
    camera's frame and from it to the hand; the first camera's ``X_CE`` is ``X_CE``."""
    run = _run(apollo)
    builder = DiagramBuilder()
    source = builder.AddSystem(RecordedRunSource(run))
    tracker = _add(builder, two_cameras, source, [
        TrackerCamera(name, CAMERA, source.get_depth_frame_output_port(name))
        for name in ("camera", "post")])
    bank = tracker.kalman_bank
    context = bank.CreateDefaultContext()
    model = two_cameras
    rng = np.random.default_rng(462)
    q = rng.normal(0.0, 0.3, model.num_joints)
    for name in model.camera_names:
        q[model.camera_joint_indices(name)] = rng.normal(0.0, [0.02] * 3 + [0.03] * 3)
    belief = bank.belief(context).copy()
    belief[0] = q
    context.SetDiscreteState(0, belief.reshape(-1))
    plant = model.plant
    plant_context = plant.CreateDefaultContext()
    plant.SetPositions(plant_context, q)
    for name in model.camera_names:
        X_WC = plant.CalcRelativeTransform(plant_context, plant.world_frame(),
                                           model.camera(name).frame)
        np.testing.assert_allclose(
            bank.GetOutputPort(f"{name}_X_WC").Eval(context).GetAsMatrix4(),
            X_WC.GetAsMatrix4(), atol=1e-9)
        X_CE = plant.CalcRelativeTransform(plant_context, model.camera(name).frame,
                                           model.end_effector_frame)
        port = tracker.camera_hand_poses[name]
        assert port.get_name() == f"{name}_X_CE"
        np.testing.assert_allclose(port.Eval(context).GetAsMatrix4(), X_CE.GetAsMatrix4(),
                                   atol=1e-9)
    np.testing.assert_allclose(tracker.camera_hand_poses["camera"].Eval(context).GetAsMatrix4(),
                               bank.GetOutputPort("X_CE").Eval(context).GetAsMatrix4(),
                               atol=1e-12)
