"""Several depth cameras in one tracker (issue 46): each camera with its own six virtual
offset joints, its images scored through its own offset, one delay buffer."""

import dataclasses
import logging

import numpy as np
import pytest
from fast_params import seeded_params
from two_cameras import CAMERA, POST, two_camera_config

from drake_tracker.core.filter.estimate import estimate_from_belief
from drake_tracker.core.render.kinematics import BatchedKinematics
from drake_tracker.core.sensors.depth_frames import DepthFrame
from drake_tracker.io.recording import CameraImages, RecordedRun
from drake_tracker.io.replay import replay_run
from drake_tracker.io.synthetic import synthetic_run
from drake_tracker.params.resolve import resolve_tracker_params
from drake_tracker.robot.model import (
    VIRTUAL_JOINT_NAMES,
    CameraMount,
    FrameOffset,
    build_tracker_model,
    camera_offset_transform,
    robot_preset,
)
from drake_tracker.sim.scenario.checks import validate_scenario
from drake_tracker.sim.scenario.load import load_scenario
from drake_tracker.tracker import Tracker


@pytest.fixture(scope="module")
def two_cameras():
    return build_tracker_model(two_camera_config())


def test_each_camera_has_its_own_six_joints_and_one_camera_keeps_its_names(apollo,
                                                                           two_cameras):
    assert apollo.camera_names == ["camera"]
    assert [apollo.joint_names[k] for k in apollo.virtual_joint_indices] == list(
        VIRTUAL_JOINT_NAMES)
    assert VIRTUAL_JOINT_NAMES[0] == "camera_offset_x"
    assert apollo.camera_frame.body().name() == "camera_offset_estimated_camera"
    assert two_cameras.camera_names == ["camera", "post"]
    assert two_cameras.joint_names[:len(apollo.joint_names)] == apollo.joint_names
    post = [two_cameras.joint_names[k] for k in two_cameras.camera_joint_indices("post")]
    assert post == ["post_offset_x", "post_offset_y", "post_offset_z", "post_offset_rx",
                    "post_offset_ry", "post_offset_rz"]
    assert len(two_cameras.virtual_joint_indices) == 12
    assert two_cameras.robot_joint_names == apollo.robot_joint_names
    view = two_cameras.for_camera("post")
    assert view.camera_frame.body().name() == "post_offset_estimated_camera"
    assert view.nominal_camera_frame.name() == "post_nominal"


def test_a_camera_is_seen_through_its_own_offset_as_drake_computes_it(two_cameras):
    """X_nominal_estimated of each camera from Drake's kinematics equals the offset
    transform of its own six joints, and the renderer's kinematics agree with Drake."""
    model = two_cameras
    plant = model.plant
    context = plant.CreateDefaultContext()
    rng = np.random.default_rng(46)
    q = np.zeros(model.num_joints)
    offsets = {name: rng.normal(0.0, [0.02] * 3 + [0.03] * 3) for name in model.camera_names}
    for name, offset in offsets.items():
        q[model.camera_joint_indices(name)] = offset
    plant.SetPositions(context, q)
    kinematics = BatchedKinematics.from_plant(plant)
    for name in model.camera_names:
        camera = model.camera(name)
        X = plant.CalcRelativeTransform(context, camera.nominal_frame, camera.frame)
        np.testing.assert_allclose(X.GetAsMatrix4(), camera_offset_transform(offsets[name]),
                                   atol=1e-12)
        hand = plant.CalcRelativeTransform(context, camera.frame, model.end_effector_frame)
        X_CB = kinematics.relative_poses(q[None], camera.frame)[0]
        body = int(model.end_effector_frame.body().index())
        X_BE = model.end_effector_frame.GetFixedPoseInBodyFrame().GetAsMatrix4()
        np.testing.assert_allclose(X_CB[body] @ X_BE, hand.GetAsMatrix4(), atol=1e-9)


def joints_that_move(model, frame) -> set[int]:
    """Indices of the robot joints that move ``frame`` in the world, by Drake: each
    joint turned 0.3 rad alone."""
    plant = model.plant
    context = plant.CreateDefaultContext()
    q0 = plant.GetPositions(context)
    X0 = frame.CalcPoseInWorld(context).GetAsMatrix4()
    moving = set()
    for k in model.robot_joint_indices:
        q = q0.copy()
        q[k] += 0.3
        plant.SetPositions(context, q)
        if not np.allclose(frame.CalcPoseInWorld(context).GetAsMatrix4(), X0, atol=1e-9):
            moving.add(int(k))
        plant.SetPositions(context, q0)
    return moving


def test_an_image_moves_the_robot_and_its_own_camera_only(two_cameras):
    """Each camera's images sample its own six offset joints and the robot joints, but
    neither another camera's offset joints nor the joints that move another camera and
    not this one (the head's pan and tilt, for the camera on the post)."""
    params = resolve_tracker_params(seeded_params(), two_cameras)
    head = joints_that_move(two_cameras, two_cameras.camera("camera").nominal_frame)
    assert {two_cameras.joint_names[k] for k in head} == {"head_pan", "head_tilt"}
    assert joints_that_move(two_cameras, two_cameras.camera("post").nominal_frame) == set()
    robot = set(two_cameras.robot_joint_indices.tolist())
    for name, others_chain in (("camera", set()), ("post", head)):
        own = set(two_cameras.camera_joint_indices(name).tolist())
        other = set(two_cameras.virtual_joint_indices.tolist()) - own
        sampled = set(np.concatenate(params.blocks_for(name)).tolist())
        assert own <= sampled and not sampled & other
        assert sampled & robot == robot - others_chain


def test_a_second_camera_without_images_gives_the_one_camera_estimate(apollo, two_cameras):
    """A two-camera model fed the images of its first camera only estimates what the
    one-camera model does (to rounding: the arrays are longer), its second camera's
    offset staying at its prior;
    an image of the second camera that sees nothing changes nothing."""
    run = synthetic_run(apollo, duration_s=0.6, camera=CAMERA, seed=3)
    one = replay_run(run, seeded_params(), apollo)
    two = replay_run(run, seeded_params(), two_cameras)
    n = apollo.num_joints
    np.testing.assert_allclose(two.positions[:, :n], one.positions, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(two.X_CE, one.X_CE, rtol=1e-9, atol=1e-12)
    post = two_cameras.camera_joint_indices("post")
    sampled = np.isfinite(two.positions[:, 0])
    np.testing.assert_array_equal(two.positions[sampled][:, post], 0.0)
    tracker = Tracker(two_cameras, params=seeded_params(), cameras={"camera": CAMERA,
                                                                   "post": CAMERA})
    tracker.add_reading(0.0, np.zeros(len(two_cameras.robot_joint_names)))
    tracker.add_reading(0.05, np.zeros(len(two_cameras.robot_joint_names)))
    before = tracker.estimate().positions
    blank = np.full((60, 80), np.nan, np.float32)
    assert not tracker.add_image(DepthFrame(0.02, 0.05, blank, 0), camera="post")
    np.testing.assert_array_equal(tracker.estimate().positions, before)


def test_bad_cameras_name_the_problem(two_cameras, caplog):
    config = two_camera_config()
    config.cameras[1].name = "camera"
    with pytest.raises(ValueError, match="two cameras are named 'camera'"):
        build_tracker_model(config)
    config = two_camera_config()
    config.added_frames = {}
    with pytest.raises(ValueError, match=r"cameras\[post\].frame.*post_nominal"):
        build_tracker_model(config)
    with pytest.raises(ValueError, match="unknown camera 'side'"):
        Tracker(two_cameras, params=seeded_params(), cameras={"side": CAMERA})
    with pytest.raises(ValueError, match="one of the two"):
        Tracker(two_cameras, CAMERA, seeded_params(), cameras={"camera": CAMERA})
    tracker = Tracker(two_cameras, params=seeded_params(), cameras={"camera": CAMERA,
                                                                   "post": CAMERA})
    n = len(two_cameras.robot_joint_names)
    for k in range(30):
        tracker.add_reading(0.1 * k, np.zeros(n))
    image = np.full((60, 80), 2.0, np.float32)
    with pytest.raises(ValueError, match="unknown camera 'side'.*'camera', 'post'"):
        tracker.add_image(DepthFrame(2.0, 2.05, image, 0), camera="side")
    with pytest.raises(ValueError, match="name the image's camera"):
        tracker.add_image(DepthFrame(2.0, 2.05, image, 0))
    # A camera whose clock is 5 s off the other's (more than the buffer horizon).
    assert tracker.add_image(DepthFrame(2.0, 2.05, image, 0), camera="camera") in (True, False)
    with caplog.at_level(logging.WARNING):
        assert not tracker.add_image(DepthFrame(-3.0, 2.1, image, 0), camera="post")
    assert "camera 'post''s clock disagrees with camera 'camera''s" in caplog.text
    assert tracker.warnings.counts["images whose camera clock disagrees"] == 1


def two_camera_run(apollo):
    run = synthetic_run(apollo, duration_s=0.3, camera=CAMERA, seed=1)
    T = len(run.truth_times_s)
    post = CameraImages("post", CAMERA.subsampled(2), run.image_capture_times_s + 0.01,
                        run.image_arrival_times_s + 0.02,
                        run.depth_images_m[:, ::2, ::2].copy(),
                        np.tile(np.arange(6.0), (T, 1)))
    return dataclasses.replace(run, other_cameras=[post])


def test_a_two_camera_recording_round_trips_and_version_1_still_reads(apollo, tmp_path):
    run = two_camera_run(apollo)
    loaded = RecordedRun.load(run.save(tmp_path / "two.npz"))
    assert loaded.camera_names == ["camera", "post"]
    mine, theirs = run.other_cameras[0], loaded.other_cameras[0]
    assert theirs.intrinsics == mine.intrinsics
    for name in ("capture_times_s", "arrival_times_s", "depth_images_m",
                 "truth_camera_offset"):
        np.testing.assert_array_equal(getattr(theirs, name), getattr(mine, name))
    np.testing.assert_array_equal(loaded.depth_images_m, run.depth_images_m)
    # A version 1 file: the keys of before, without the cameras.
    one = dataclasses.replace(run, other_cameras=[])
    with np.load(one.save(tmp_path / "one.npz")) as data:
        keys = {k: data[k] for k in data.files if k != "camera_names"}
    keys["format_version"] = np.array(1)
    np.savez_compressed(tmp_path / "v1.npz", **keys)
    old = RecordedRun.load(tmp_path / "v1.npz")
    assert old.camera_names == ["camera"] and not old.other_cameras
    np.testing.assert_array_equal(old.depth_images_m, run.depth_images_m)
    with pytest.raises(ValueError, match="same name"):
        dataclasses.replace(run, other_cameras=[dataclasses.replace(mine, name="camera")])


def test_two_camera_presets_declare_two_mounted_cameras():
    scenario = load_scenario("in-out-in-2cam/constant")
    config = scenario.resolved_robot_config()
    assert [m.name for m in config.cameras] == ["camera", "post_camera"]
    assert config.cameras[1].frame in config.added_frames
    assert scenario.camera == scenario.cameras[0].sensor()
    assert scenario.cameras[0].offset != scenario.cameras[1].offset
    scenario.cameras[1].name = "camera"
    with pytest.raises(ValueError, match="two cameras have this name"):
        validate_scenario(scenario, check_model=False)


def test_an_image_of_one_of_several_cameras_that_shows_no_arm_is_not_applied(apollo):
    """A camera that looks away from the robot (3 m above the torso, looking up): with
    another camera, its image is skipped and counted (it could only push the joints it
    sees away from its view) and the estimate stays bit for bit; as the only camera, the
    same image is applied."""
    up = FrameOffset(parent="torso", xyz_m=[0.0, 0.0, 3.0])
    config = two_camera_config()
    config.added_frames = {"post_nominal": POST, "up_nominal": up}
    config.cameras = [CameraMount("camera", "camera_optical"), CameraMount("up", "up_nominal")]
    alone = robot_preset("apollo")
    alone.added_frames = {"up_nominal": up}
    alone.cameras = [CameraMount("up", "up_nominal")]
    wall = np.full((60, 80), 2.0, np.float32)
    applied = {}
    for label, model, cameras in (("several", build_tracker_model(config), {"camera": CAMERA,
                                                                            "up": CAMERA}),
                                  ("alone", build_tracker_model(alone), {"up": CAMERA})):
        tracker = Tracker(model, params=seeded_params(), cameras=cameras)
        n = len(model.robot_joint_names)
        for k in range(10):
            tracker.add_reading(0.01 * k, np.full(n, 0.1))
        before = tracker.estimate().positions
        applied[label] = tracker.add_image(DepthFrame(0.05, 0.08, wall, 0), camera="up")
        if label == "several":
            np.testing.assert_array_equal(tracker.estimate().positions, before)
            assert tracker.warnings.counts["images that show no arm"] == 1
    assert applied == {"several": False, "alone": True}


def test_the_reported_health_is_the_first_cameras_while_it_tracks():
    """The health describes X_CE, in the first camera's frame: another camera that
    tracks the arm makes it at best uncertain; one camera reports its own."""
    from types import SimpleNamespace

    from drake_tracker.core.cameras import best_health
    from drake_tracker.core.robustness.health import HealthState, TrackerHealth

    def channels(*states):
        return {f"c{k}": SimpleNamespace(health=TrackerHealth(state, restarts=k))
                for k, state in enumerate(states)}

    T, U, L = HealthState.TRACKING, HealthState.UNCERTAIN, HealthState.LOST
    assert best_health(channels(T, L)).restarts == 0
    assert best_health(channels(U, T)).state == U
    assert best_health(channels(U, T)).restarts == 1  # the best camera's counts
    assert best_health(channels(L, U)).state == U
    assert best_health(channels(L, L)).state == L
    for state in (T, U, L):
        assert best_health(channels(state)).state == state


def test_the_estimate_gives_the_hand_in_every_cameras_frame_as_drake_computes_it(
        two_cameras):
    """``TrackerEstimate.X_WC_by_camera`` and ``X_CkE`` at the estimate's positions equal
    Drake's ``CalcRelativeTransform`` there; the first camera's ``X_CkE`` is ``X_CE``."""
    model = two_cameras
    tracker = Tracker(model, params=seeded_params(), cameras={"camera": CAMERA, "post": CAMERA})
    rng = np.random.default_rng(461)
    n = len(model.robot_joint_names)
    tracker.add_reading(0.0, rng.normal(0.0, 0.3, n))
    tracker.add_reading(0.01, rng.normal(0.0, 0.3, n))
    estimate = tracker.estimate()
    q = estimate.positions.copy()
    for name in model.camera_names:  # offsets away from 0, as after images
        q[model.camera_joint_indices(name)] = rng.normal(0.0, [0.02] * 3 + [0.03] * 3)
    belief = np.zeros((5, model.num_joints))
    belief[0] = q
    estimate = estimate_from_belief(model, tracker.readout, 0.01, belief)
    plant = model.plant
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, q)
    assert list(estimate.X_WC_by_camera) == ["camera", "post"]
    for name in model.camera_names:
        frame = model.camera(name).frame
        X_WC = plant.CalcRelativeTransform(context, plant.world_frame(), frame)
        np.testing.assert_allclose(estimate.X_WC_by_camera[name], X_WC.GetAsMatrix4(),
                                   atol=1e-9)
        X_CE = plant.CalcRelativeTransform(context, frame, model.end_effector_frame)
        np.testing.assert_allclose(estimate.X_CkE(name), X_CE.GetAsMatrix4(), atol=1e-9)
    np.testing.assert_allclose(estimate.X_CkE("camera"), estimate.X_CE, atol=1e-12)
    with pytest.raises(ValueError, match="unknown camera 'side'.*'camera', 'post'"):
        estimate.X_CkE("side")
