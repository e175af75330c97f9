"""A robot's prismatic joints (a gripper's fingers) are filtered in metres: they get
``kalman.prismatic_joints`` (a 1 cm bias prior), not the revolute defaults (0.1 rad,
which as metres let the Panda's fingers drift 3 cm below their limit), in the bank, the
image update's priors and every method."""

import numpy as np
import pytest

from drake_tracker.evaluation.methods import method_params
from drake_tracker.params.loading import load_tracker_params
from drake_tracker.params.resolve import joint_noise_for, resolve_kalman_params
from drake_tracker.params.tracker_params import JointNoise, TrackerParams
from drake_tracker.robot.model import (
    VIRTUAL_JOINT_NAMES,
    FrameOffset,
    RobotConfig,
    build_tracker_model,
)

URDF = """<?xml version="1.0"?>
<robot name="slider">
  <link name="base"><visual><geometry><box size="0.1 0.1 0.1"/></geometry></visual></link>
  <link name="arm"><visual><geometry><box size="0.05 0.05 0.3"/></geometry></visual>
    <inertial><mass value="1"/><inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0"
      iyz="0"/></inertial></link>
  <link name="finger"><visual><geometry><box size="0.02 0.02 0.05"/></geometry></visual>
    <inertial><mass value="0.1"/><inertia ixx="0.001" iyy="0.001" izz="0.001" ixy="0"
      ixz="0" iyz="0"/></inertial></link>
  <joint name="turn" type="revolute"><parent link="base"/><child link="arm"/>
    <axis xyz="0 0 1"/><limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
  <joint name="slide" type="prismatic"><parent link="arm"/><child link="finger"/>
    <origin xyz="0 0 0.3"/><axis xyz="1 0 0"/>
    <limit lower="0" upper="0.04" effort="1" velocity="1"/></joint>
</robot>
"""


@pytest.fixture(scope="module")
def slider(tmp_path_factory):
    path = tmp_path_factory.mktemp("slider") / "slider.urdf"
    path.write_text(URDF)
    return build_tracker_model(RobotConfig(
        model_file=str(path), camera_frame="camera", end_effector_frame="finger",
        added_frames={"camera": FrameOffset(parent="base", xyz_m=[1.0, 0.0, 0.2],
                                            rpy_deg=[-90.0, 0.0, 90.0])}))


def test_the_prismatic_joint_gets_the_metre_defaults(slider):
    assert slider.prismatic_joint_names == ["slide"]  # the camera's x, y, z are virtual
    params = TrackerParams()
    noise = dict(zip(slider.joint_names, joint_noise_for(
        params, slider.joint_names, slider.prismatic_joint_names)))
    assert noise["slide"] == params.kalman.prismatic_joints
    assert noise["turn"] == params.kalman.robot_joints
    assert all(noise[n] == params.kalman.virtual_joints for n in VIRTUAL_JOINT_NAMES)
    assert params.kalman.prismatic_joints.initial_bias_std_rad == 0.01  # 1 cm
    bank = resolve_kalman_params(params, slider.joint_names, slider.prismatic_joint_names)
    k = slider.joint_names.index("slide")
    assert bank.encoder_noise_std[k] == 2e-5 and bank.bias_process_std[k] == 0.002
    # An override still wins; without the prismatic names, the revolute defaults.
    params.kalman.overrides["slide"] = JointNoise(has_bias=False)
    assert joint_noise_for(params, slider.joint_names, ["slide"])[k].has_bias is False
    assert joint_noise_for(TrackerParams(), slider.joint_names)[k] == JointNoise()


def test_every_method_treats_the_prismatic_joints_as_the_revolute_ones():
    for method in ("camera_offset_only", "vision_only"):
        k = method_params(method).kalman
        assert not k.robot_joints.has_bias and not k.prismatic_joints.has_bias
    unread = method_params("vision_only").kalman
    assert unread.prismatic_joints.initial_angle_std_rad == pytest.approx(
        0.1 * unread.robot_joints.initial_angle_std_rad)  # 1 cm against 0.1 rad


def test_a_bad_prismatic_default_is_named_at_load(tmp_path):
    path = tmp_path / "params.yaml"
    path.write_text("kalman: {prismatic_joints: {initial_bias_std_rad: -0.01}}\n")
    with pytest.raises(ValueError, match="kalman.prismatic_joints.initial_bias_std_rad"):
        load_tracker_params(path)


def test_the_tracker_starts_with_the_metre_prior_on_the_finger(slider):
    from drake_tracker.core.filter.kalman import VAR_B
    from drake_tracker.core.filter.start import new_bank_and_belief
    from drake_tracker.params.resolve import resolve_tracker_params

    _, prior = new_bank_and_belief(resolve_tracker_params(TrackerParams(), slider), np.array([0.3,
    0.02]))
    k = slider.joint_names.index("slide")
    assert prior[VAR_B, k] == pytest.approx(0.01 ** 2)
    assert prior[VAR_B, slider.joint_names.index("turn")] == pytest.approx(0.1 ** 2)
