"""The pose readout: one configuration through the serial kernel gives exactly what the
batched kinematics give."""

import numpy as np
import pytest
from pydrake.math import RigidTransform

from drake_tracker.core.filter.estimate import PoseReadout
from drake_tracker.robot.model import build_tracker_model, robot_preset


@pytest.fixture(scope="module")
def arm6():
    return build_tracker_model(robot_preset("arm6"))


@pytest.mark.parametrize("robot", ["apollo", "arm6"])
def test_one_configuration_gives_exactly_the_batched_poses(robot, request):
    model = request.getfixturevalue(robot)
    readout = PoseReadout(model)
    kinematics = readout.kinematics
    q = np.random.default_rng(1).normal(0.0, 1.0, (50, model.num_joints))
    batched = readout.poses(q)  # N > 1: the parallel kernel
    for k in range(len(q)):
        np.testing.assert_array_equal(readout.body_poses(q[k]), kinematics.body_poses(q[k]))
        X_WC = kinematics.frame_poses(q[k], model.camera_frame)
        X_WE = kinematics.frame_poses(q[k], model.end_effector_frame)
        # X_CE against Drake's inverse and composition (to rounding); the rest exact
        X_CE = (RigidTransform(X_WC[0]).inverse() @ RigidTransform(X_WE[0])).GetAsMatrix4()
        plain = (X_CE[None], X_WE, X_WC)
        for i, (one, expected, many) in enumerate(zip(readout.poses(q[k]), plain, batched)):
            assert one.shape == (1, 4, 4)
            np.testing.assert_allclose(one, expected, rtol=0, atol=1e-15 if i == 0 else 0)
            np.testing.assert_array_equal(one[0], many[k])


def test_non_finite_positions_are_refused_on_either_path(apollo):
    readout = PoseReadout(apollo)
    q = np.zeros(apollo.num_joints)
    q[2] = np.nan
    for bad in (q, np.array([q, q])):
        with pytest.raises(ValueError, match="NaN or infinite"):
            readout.poses(bad)


def test_the_readout_loads_its_kernel_when_made_and_a_context_adds_no_signature(apollo):
    """A Diagram's first hand pose must not stall the Simulator on numba's cache: the
    kernel is loaded when the readout is made, and a Context's read-only state reaches
    it with the same signature as an array of one's own."""
    from drake_tracker.core.render.kinematics import relative_poses_one
    from drake_tracker.params.tracker_params import TrackerParams
    from drake_tracker.systems.kalman_bank_system import JointKalmanBankSystem

    bank = JointKalmanBankSystem(model=apollo, params=TrackerParams(), period_s=1e-3)
    signatures = list(relative_poses_one.signatures)
    assert signatures  # loaded by the readout
    context = bank.CreateDefaultContext()
    assert not bank.belief(context).flags.writeable  # what the outputs read
    X_CE = bank.GetOutputPort("X_CE").Eval(context).GetAsMatrix4()
    assert list(relative_poses_one.signatures) == signatures
    np.testing.assert_array_equal(X_CE, PoseReadout(apollo).poses(
        np.zeros(apollo.num_joints))[0][0])
