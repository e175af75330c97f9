"""The joint Kalman bank system through its ports: the bank's filter, its pose outputs
against Drake's forward kinematics, a correction adopted, a NaN reading skipped."""

import numpy as np
from pydrake.systems.analysis import Simulator

from drake_tracker.core.filter.kalman import MEAN_A, JointKalmanBank
from drake_tracker.core.image_step import full_reading, make_bank_and_prior
from drake_tracker.params.tracker_params import TrackerParams, resolve_kalman_params
from drake_tracker.systems.kalman_bank_system import JointKalmanBankSystem
from drake_tracker.systems.messages import BeliefCorrection


def params() -> TrackerParams:
    p = TrackerParams()
    p.image.num_particles = 40
    return p


def test_kalman_bank_system_matches_the_bank_through_its_ports(apollo):
    p = params()
    system = JointKalmanBankSystem(apollo, p, period_s=0.01)
    context = system.CreateDefaultContext()
    n_robot = len(apollo.robot_joint_names)
    system.GetInputPort("correction").FixValue(context, BeliefCorrection())
    rng = np.random.default_rng(3)
    readings = rng.normal(0.0, 0.3, (4, n_robot))
    bank = JointKalmanBank(resolve_kalman_params(p, apollo.joint_names))
    _, expected = make_bank_and_prior(apollo, p, readings[0])
    simulator = Simulator(system, context)
    last_t = 0.0
    for k, reading in enumerate(readings):
        t = 0.01 * k
        system.GetInputPort("measured_position").FixValue(context, reading)
        system.GetInputPort("measurement_time").FixValue(context, [t])
        simulator.AdvanceTo(t + 0.005)
        expected = bank.step(expected, t - last_t, full_reading(apollo, reading))
        last_t = t
        np.testing.assert_allclose(
            system.GetOutputPort("estimated_position").Eval(context), expected[MEAN_A],
            rtol=0, atol=1e-12)
    # The same stamp again is not a new reading.
    simulator.AdvanceTo(0.045)
    np.testing.assert_allclose(system.GetOutputPort("belief").Eval(context),
                               expected.ravel(), atol=1e-12)
    # The three poses (one cached computation) against Drake's forward kinematics.
    plant = apollo.plant
    plant_context = plant.CreateDefaultContext()
    plant.SetPositions(plant_context, expected[MEAN_A])
    world = plant.world_frame()
    for name, (A, B) in {"X_CE": (apollo.camera_frame, apollo.end_effector_frame),
                         "X_WE": (world, apollo.end_effector_frame),
                         "X_WC": (world, apollo.camera_frame)}.items():
        np.testing.assert_allclose(
            system.GetOutputPort(name).Eval(context).GetAsMatrix4(),
            plant.CalcRelativeTransform(plant_context, A, B).GetAsMatrix4(), atol=1e-12)
    np.testing.assert_allclose(system.GetOutputPort("camera_offset").Eval(context),
                               expected[MEAN_A, apollo.virtual_joint_indices], atol=1e-12)


def test_kalman_bank_system_adopts_a_correction_and_skips_nan(apollo):
    p = params()
    system = JointKalmanBankSystem(apollo, p, period_s=0.01)
    context = system.CreateDefaultContext()
    n = apollo.num_joints
    corrected = np.zeros((5, n))
    corrected[MEAN_A] = 0.123
    corrected[2] = 1e-4
    system.GetInputPort("correction").FixValue(context, BeliefCorrection(1, 0.0, 0.0, corrected))
    system.GetInputPort("measured_position").FixValue(
        context, np.full(len(apollo.robot_joint_names), np.nan))
    system.GetInputPort("measurement_time").FixValue(context, [0.0])
    Simulator(system, context).AdvanceTo(0.005)
    np.testing.assert_array_equal(system.GetOutputPort("estimated_position").Eval(context),
                                  corrected[MEAN_A])
