"""One of several cameras whose own pose went wrong while the others hold the arm: its
pose restarts (``EncoderSearch.remounted``) or is searched again
(``EncoderSearch.remount_search``), the arm and the other cameras kept."""

import logging
from dataclasses import replace

import numpy as np
from fast_params import seeded_params
from two_cameras import CAMERA, two_camera_config

from drake_tracker.core.sensors.depth_frames import DepthFrame
from drake_tracker.params.resolve import resolve_tracker_params
from drake_tracker.robot.model import build_tracker_model


def _post_camera_on_the_arm(min_robot_pixels: int | None = None):
    """The post camera of two (no restart from the encoders' arm: its own decisions
    alone), the arm's true configuration, and the arm rendered from it (inf: none)."""
    from drake_tracker.core.image_processor import ImageProcessor

    model = build_tracker_model(two_camera_config())
    params = seeded_params()
    if min_robot_pixels is not None:
        params.health.min_robot_pixels = min_robot_pixels
    params.use_joint_readings = False
    resolved = resolve_tracker_params(params, model)
    post = ImageProcessor(model, CAMERA, resolved, camera_name="post")
    truth = np.zeros(model.num_joints)
    for name, angle in {"arm_joint_1": 0.35, "arm_joint_2": 1.05, "arm_joint_4": -1.05,
                        "arm_joint_6": -0.5, "head_tilt": 0.56}.items():
        truth[model.joint_names.index(name)] = angle
    return model, resolved, post, truth, post.update.renderer.render(truth[None])[0]


def test_a_camera_whose_pose_hides_the_arm_it_sees_restarts_its_own_pose_only():
    """One of several cameras whose estimated pose is 10-20 cm behind its true one sees
    the arm nearer than the estimate puts it: all but a few of its pixels read as hidden,
    which alone would skip the image. Seen through the camera's nominal mount the held
    arm agrees, so the camera's own six offset joints restart (the arm and the other
    camera's joints are kept) and the image is applied; a plate in front of the arm,
    which hides the arm from the nominal mount too, is still skipped."""
    from drake_tracker.core.filter.kalman import MEAN_A, MEAN_B, initial_moments

    model, resolved, post, truth, arm = _post_camera_on_the_arm(min_robot_pixels=100)
    image = np.where(np.isfinite(arm), arm, 3.0).astype(np.float32)
    plate = np.where(np.isfinite(arm), 0.5, 3.0).astype(np.float32)
    z = model.joint_names.index("post_offset_z")
    own = set(model.camera_joint_indices("post").tolist())
    for behind_m in (0.1, 0.2):
        prior = initial_moments(truth, resolved.joints.initial_angle_std,
                                resolved.joints.initial_bias_std, resolved.joints.has_bias)
        prior[MEAN_A, z], prior[MEAN_B, z] = -behind_m, behind_m
        out = post.observe(DepthFrame(0.0, 0.01, image, 0), prior)
        assert out.restarted and out.observation is not None
        assert out.consistency.agreement > 0.9
        assert abs(out.result.mean[z]) < 0.01  # back at the nominal mount, within 1 cm
        kept = set(out.observation.restart.untouched.tolist())
        assert kept == set(range(model.num_joints)) - own
        hidden = post.observe(DepthFrame(0.0, 0.01, plate, 1), prior)
        assert hidden.observation is None and not hidden.restarted
        assert "other cameras hold the arm" in hidden.skip_reason


def test_a_camera_whose_pose_drifted_is_searched_again_with_the_held_arm_kept(caplog):
    """The head camera of two, its pan 12 deg off (its bias estimate drifted while the arm
    was out of its view), sees the held arm: the image contradicts the arm where the
    estimate puts it, and so does the encoders' arm (biased 14 deg on four joints), so
    neither the update nor a restart of the arm can explain it. The search of the
    camera's own pose (its pan, tilt and six offset joints, restarted at their readings
    and the nominal mount) does: it is adopted, the pan comes back within 1 deg, and every
    other joint keeps its prior to the last bit. With the pan right, no such search; nor
    before the camera has once held the arm (its pose is then the start-up search's)."""
    from drake_tracker.core.filter.kalman import MEAN_A, MEAN_B, VAR_A, initial_moments
    from drake_tracker.core.image_processor import ImageProcessor
    from drake_tracker.core.robustness.health import (
        HealthState,
        ImageConsistency,
        TrackerHealth,
    )

    model = build_tracker_model(two_camera_config())
    resolved = resolve_tracker_params(seeded_params(), model)
    head = ImageProcessor(model, CAMERA, resolved, camera_name="camera")
    names = model.joint_names
    truth = np.zeros(model.num_joints)
    for name, angle in {"arm_joint_1": 0.35, "arm_joint_2": 1.05, "arm_joint_4": -1.05,
                        "arm_joint_6": -0.5, "head_tilt": 0.56}.items():
        truth[names.index(name)] = angle
    arm = head.update.renderer.render(truth[None])[0]
    image = np.where(np.isfinite(arm), arm, 3.0).astype(np.float32)
    pan = names.index("head_pan")
    own = set(model.camera_joint_indices("camera").tolist()) | {pan,
                                                                 names.index("head_tilt")}
    # The camera has not held the arm for a while (no second opinion), and its previous
    # image contradicted it too.
    held = TrackerHealth(HealthState.UNCERTAIN, acquired=False, surprising_in_a_row=1,
                         confirmed_s=-3.0,
                         latest=ImageConsistency(0.0, 900.0, 0.1, 0.3, 0.3))
    never = replace(held, confirmed_s=-np.inf)
    for offset_deg, health, expected in ((12.0, held, True), (0.0, held, False),
                                         (12.0, never, False)):
        prior = initial_moments(truth, resolved.joints.initial_angle_std,
                                resolved.joints.initial_bias_std, resolved.joints.has_bias)
        prior[VAR_A] = np.minimum(prior[VAR_A], np.radians(0.5) ** 2)  # a held belief
        for name in ("arm_joint_1", "arm_joint_2", "arm_joint_4", "arm_joint_6"):
            prior[MEAN_B, names.index(name)] = 0.25  # biased readings
        prior[MEAN_A, pan] += np.radians(offset_deg)  # the reading is the true pan
        prior[MEAN_B, pan] -= np.radians(offset_deg)
        with caplog.at_level(logging.WARNING):
            caplog.clear()
            out = head.observe(DepthFrame(0.0, 0.01, image, 0), prior, health=health)
        searched = "a search of this camera's own pose" in caplog.text
        assert searched == expected and out.restarted == expected
        if not expected:
            continue
        assert abs(np.degrees(out.result.mean[pan] - truth[pan])) < 1.0
        others = sorted(set(range(model.num_joints)) - own)
        assert sorted(out.observation.restart.untouched.tolist()) == others
        np.testing.assert_array_equal(out.result.mean[others], prior[MEAN_A, others])


def test_an_image_that_hides_most_of_the_arm_is_skipped_while_another_camera_tracks_it():
    """One of several cameras sees a plate hide most of the arm where the estimate puts
    it (the true arm behind it): while another camera tracks the arm, the image is not
    applied (its few unhidden pixels would pin this camera's own pose); while none
    does, it is, as the images of a camera alone are."""
    from drake_tracker.core.cameras import another_camera_tracks
    from drake_tracker.core.filter.kalman import initial_moments
    from drake_tracker.core.robustness.health import HealthState, TrackerHealth

    model, resolved, post, truth, arm = _post_camera_on_the_arm()
    rows = np.flatnonzero(np.isfinite(arm).any(axis=1))
    cut = rows[int(0.7 * len(rows))]  # the plate hides the arm's rows above this one
    plate = np.where(np.isfinite(arm), arm, 3.0)
    plate[:cut][np.isfinite(arm[:cut])] = 0.5
    plate = plate.astype(np.float32)
    prior = initial_moments(truth, resolved.joints.initial_angle_std,
                            resolved.joints.initial_bias_std, resolved.joints.has_bias)
    held = post.observe(DepthFrame(0.0, 0.01, plate, 0), prior, others_track=True)
    seen = held.consistency
    assert seen.occluded > 0.5 and seen.visible_robot_pixels >= resolved.health.min_robot_pixels
    assert held.observation is None and not held.restarted
    assert "hidden" in held.skip_reason and "other cameras hold the arm" in held.skip_reason
    alone = post.observe(DepthFrame(0.0, 0.01, plate, 0), prior, others_track=False)
    assert alone.observation is not None and alone.skip_reason == ""
    # Which cameras count: any other that says tracking, never the camera itself.
    healths = {"camera": TrackerHealth(HealthState.UNCERTAIN),
               "post": TrackerHealth(HealthState.TRACKING)}
    assert another_camera_tracks(healths, "camera")
    assert not another_camera_tracks(healths, "post")
