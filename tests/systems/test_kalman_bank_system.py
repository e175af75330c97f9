"""The joint Kalman bank system through its ports: the bank's filter on the readings the
delay buffer admitted, its pose outputs against Drake's forward kinematics, a correction
adopted, a reading the correction holds not filtered twice, a restart."""

import numpy as np
from pydrake.systems.analysis import Simulator

from drake_tracker.core.filter.kalman import MEAN_A, JointKalmanBank
from drake_tracker.core.filter.start import full_reading, new_bank_and_belief
from drake_tracker.params.resolve import resolve_kalman_params, resolve_tracker_params
from drake_tracker.params.tracker_params import TrackerParams
from drake_tracker.systems.kalman_bank_system import JointKalmanBankSystem
from drake_tracker.systems.messages import AdmittedReading, BeliefCorrection


def params() -> TrackerParams:
    p = TrackerParams()
    p.image.num_particles = 40
    return p


def test_kalman_bank_system_matches_the_bank_through_its_ports(apollo):
    p = params()
    system = JointKalmanBankSystem(model=apollo, params=p, period_s=0.01)
    context = system.CreateDefaultContext()
    n_robot = len(apollo.robot_joint_names)
    system.get_correction_input_port().FixValue(context, BeliefCorrection())
    rng = np.random.default_rng(3)
    readings = rng.normal(0.0, 0.3, (4, n_robot))
    bank = JointKalmanBank(resolve_kalman_params(p, apollo.joint_names))
    _, expected = new_bank_and_belief(resolve_tracker_params(p, apollo), readings[0])
    simulator = Simulator(system, context)
    last_t = 0.0
    for k, reading in enumerate(readings):
        t = 0.01 * k
        system.get_reading_input_port().FixValue(context, AdmittedReading(k + 1, t, reading))
        simulator.AdvanceTo(t + 0.005)
        expected = bank.step(expected, t - last_t, full_reading(apollo, reading))
        last_t = t
        np.testing.assert_allclose(
            system.GetOutputPort("estimated_position").Eval(context), expected[MEAN_A],
            rtol=0, atol=1e-12)
    assert system.bookkeeping(context).reading_id == len(readings)
    # The same message again is not a new reading.
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


def test_kalman_bank_system_adopts_a_correction_once_and_restarts(apollo):
    p = params()
    system = JointKalmanBankSystem(model=apollo, params=p, period_s=0.01)
    context = system.CreateDefaultContext()
    n, n_robot = apollo.num_joints, len(apollo.robot_joint_names)
    corrected = np.zeros((5, n))
    corrected[MEAN_A] = 0.123
    corrected[2] = 1e-4
    # The correction holds the reading at 0.0 already: that reading is not filtered again.
    system.get_correction_input_port().FixValue(context, BeliefCorrection(1, 0.0, 0.0,
                                                                          corrected))
    system.get_reading_input_port().FixValue(
        context, AdmittedReading(1, 0.0, np.full(n_robot, 0.5)))
    simulator = Simulator(system, context)
    simulator.AdvanceTo(0.005)
    np.testing.assert_array_equal(system.GetOutputPort("estimated_position").Eval(context),
                                  corrected[MEAN_A])
    state = system.bookkeeping(context)
    assert (state.correction_id, state.reading_id, state.time_s) == (1, 1, 0.0)
    # A reading the gate marked as a restart starts the belief again from it.
    reading = np.full(n_robot, -0.25)
    system.get_reading_input_port().FixValue(
        context, AdmittedReading(2, 5.0, reading, restarted=True))
    simulator.AdvanceTo(0.015)
    resolved = resolve_tracker_params(p, apollo)
    bank, start = new_bank_and_belief(resolved, reading)
    expected = bank.step(start, 0.0, full_reading(resolved, reading))
    np.testing.assert_allclose(system.belief(context), expected, rtol=0, atol=1e-12)
    assert system.bookkeeping(context).last_reading_s == 5.0


def test_the_bank_reads_its_correction_port_when_the_reading_tells_of_a_new_one(apollo):
    """A reading that carries the buffer's latest correction id spares the correction
    port while that id is not newer than the bank's; republished with a newer id (the
    buffer applied an image), the correction is adopted."""
    system = JointKalmanBankSystem(model=apollo, params=params(), period_s=0.01)
    context = system.CreateDefaultContext()
    n, n_robot = apollo.num_joints, len(apollo.robot_joint_names)
    corrected = np.zeros((5, n))
    corrected[MEAN_A], corrected[2] = 0.123, 1e-4
    system.get_correction_input_port().FixValue(context, BeliefCorrection(1, 0.0, 0.0,
                                                                          corrected))
    reading = np.full(n_robot, 0.5)
    system.get_reading_input_port().FixValue(
        context, AdmittedReading(1, 0.0, reading, correction_id=0))
    simulator = Simulator(system, context)
    simulator.AdvanceTo(0.005)
    assert system.bookkeeping(context).correction_id == 0  # the port was not read
    resolved = resolve_tracker_params(params(), apollo)
    bank, start = new_bank_and_belief(resolved, reading)
    np.testing.assert_array_equal(system.belief(context),
                                  bank.step(start, 0.0, full_reading(resolved, reading)))
    system.get_reading_input_port().FixValue(
        context, AdmittedReading(1, 0.0, reading, correction_id=1))
    simulator.AdvanceTo(0.015)
    assert system.bookkeeping(context).correction_id == 1
    np.testing.assert_array_equal(system.belief(context), corrected)
