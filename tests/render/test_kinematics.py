"""BatchedKinematics against MultibodyPlant on both shipped robots."""

import numpy as np
import pytest
from pydrake.multibody.tree import BodyIndex, JointIndex

from drake_tracker.core.render.kinematics import BatchedKinematics
from drake_tracker.robot.model import VIRTUAL_JOINT_NAMES, build_tracker_model, robot_preset


def random_configurations(model, num: int, rng: np.random.Generator) -> np.ndarray:
    """Robot joints uniform within limits, virtual joints small offsets."""
    plant = model.plant
    lower = plant.GetPositionLowerLimits()
    upper = plant.GetPositionUpperLimits()
    lower = np.where(np.isfinite(lower), lower, -np.pi)
    upper = np.where(np.isfinite(upper), upper, np.pi)
    q = rng.uniform(lower, upper, size=(num, plant.num_positions()))
    for name in VIRTUAL_JOINT_NAMES:
        k = model.joint_names.index(name)
        q[:, k] = rng.normal(0.0, 0.05, size=num)
    return q


@pytest.fixture(scope="module", params=["apollo", "arm6"])
def model(request):
    return build_tracker_model(robot_preset(request.param))


def test_joint_name_order_matches_position_order(model):
    plant = model.plant
    for i in range(plant.num_joints()):
        joint = plant.get_joint(JointIndex(i))
        if joint.num_positions() == 1:
            assert model.joint_names[joint.position_start()] == joint.name()


def test_matches_multibody_plant(model):
    rng = np.random.default_rng(1234)
    plant = model.plant
    kin = BatchedKinematics.from_plant(plant)
    assert kin.num_positions == plant.num_positions()
    assert kin.num_bodies == plant.num_bodies()
    q = random_configurations(model, 25, rng)
    X_WB = kin.body_poses(q)
    X_WE = kin.frame_poses(q, model.end_effector_frame)
    X_CB = kin.relative_poses(q, model.camera_frame)
    X_CE = np.linalg.inv(kin.frame_poses(q, model.camera_frame)) @ X_WE
    context = plant.CreateDefaultContext()
    for n in range(q.shape[0]):
        plant.SetPositions(context, q[n])
        for b in range(plant.num_bodies()):
            body = plant.get_body(BodyIndex(b))
            expected = plant.EvalBodyPoseInWorld(context, body).GetAsMatrix4()
            np.testing.assert_allclose(X_WB[n, b], expected, atol=1e-9, rtol=0)
            expected_rel = plant.CalcRelativeTransform(
                context, model.camera_frame, body.body_frame()
            ).GetAsMatrix4()
            np.testing.assert_allclose(X_CB[n, b], expected_rel, atol=1e-9, rtol=0)
        expected_ee = model.end_effector_frame.CalcPoseInWorld(context).GetAsMatrix4()
        np.testing.assert_allclose(X_WE[n], expected_ee, atol=1e-9, rtol=0)
        expected_ce = plant.CalcRelativeTransform(
            context, model.camera_frame, model.end_effector_frame
        ).GetAsMatrix4()
        np.testing.assert_allclose(X_CE[n], expected_ce, atol=1e-9, rtol=0)


def test_single_configuration_and_bad_input(model):
    kin = BatchedKinematics.from_plant(model.plant)
    nq = kin.num_positions
    assert kin.body_poses(np.zeros(nq)).shape == (1, kin.num_bodies, 4, 4)
    with pytest.raises(ValueError, match="shape"):
        kin.body_poses(np.zeros((3, nq + 1)))
    with pytest.raises(ValueError, match="shape"):
        kin.body_poses(np.zeros((2, 3, nq)))
    q = np.zeros((2, nq))
    q[1, 0] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        kin.body_poses(q)
    with pytest.raises(ValueError, match="NaN"):
        kin.relative_poses(q, model.camera_frame)
