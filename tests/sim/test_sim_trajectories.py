"""Trajectories and scenario presets: formulas, smoothness, limits, every preset valid."""

import numpy as np
import pytest

from drake_tracker.robot.model import build_tracker_model
from drake_tracker.sim.scenario.load import (
    ROBOT_PROFILES,
    TrajectoryConfig,
    list_presets,
    load_scenario,
    validate_scenario,
)
from drake_tracker.sim.trajectories import (
    check_within_limits,
    make_joint_trajectory,
    smooth_window,
)

NAMES = ["j0", "j1", "j2"]


def test_sinusoid_matches_its_formula():
    config = TrajectoryConfig(kind="sinusoid", joints=["j0", "j2"], amplitude_deg=10.0,
                              period_s=4.0, home_deg={"j1": 30.0})
    traj = make_joint_trajectory(config, NAMES, None, seed=0)
    t = np.linspace(0.0, 9.0, 50)
    q = traj.positions(t)
    A = np.radians(10.0)
    np.testing.assert_allclose(q[:, 0], A * np.sin(2 * np.pi * t / 4.0), atol=1e-12)
    np.testing.assert_allclose(q[:, 1], np.radians(30.0), atol=1e-12)
    np.testing.assert_allclose(q[:, 2], A * np.sin(2 * np.pi * t / (4.0 * 1.17) + np.pi / 3),
                               atol=1e-12)


def test_free_motion_is_seeded_bounded_and_smooth():
    config = TrajectoryConfig(kind="free", amplitude_deg=15.0, speed_scale=2.5)
    a = make_joint_trajectory(config, NAMES, None, seed=4)
    b = make_joint_trajectory(config, NAMES, None, seed=4)
    c = make_joint_trajectory(config, NAMES, None, seed=5)
    t = np.linspace(0.0, 60.0, 6001)
    qa = a.positions(t)
    np.testing.assert_array_equal(qa, b.positions(t))
    assert not np.allclose(qa, c.positions(t))
    assert np.abs(qa).max() <= np.radians(15.0) + 1e-12
    assert np.abs(qa).max() > np.radians(5.0)
    # Frequencies at most 0.15 Hz * 2.5: |dq/dt| <= A * 2 pi f_max.
    bound = np.radians(15.0) * 2 * np.pi * 0.15 * 2.5
    assert np.abs(a.velocities(t)).max() <= bound + 1e-6


def test_in_out_in_excursion_window():
    config = TrajectoryConfig(kind="in-out-in", joints=["j0"], amplitude_deg=0.0,
                              excursion_joint="j1", excursion_deg=-90.0,
                              excursion_start_s=2.0, excursion_duration_s=3.0,
                              excursion_ramp_s=1.0)
    traj = make_joint_trajectory(config, NAMES, None, seed=0)
    q = traj.positions([1.9, 2.5, 3.0, 4.0, 6.5, 7.5])[:, 1]
    np.testing.assert_allclose(np.degrees(q), [0.0, -45.0, -90.0, -90.0, -45.0, 0.0],
                               atol=1e-9)
    w = smooth_window(np.linspace(0, 10, 1001), 2.0, 3.0, 1.0)
    assert np.max(np.abs(np.diff(w))) < 0.02  # continuous, no jumps


def test_limit_check_names_the_joint():
    q = np.array([[0.0, 0.5], [0.1, 2.5]])
    with pytest.raises(ValueError, match="joint 'j1'"):
        check_within_limits(q, np.array([-1.0, -1.0]), np.array([1.0, 2.0]), ["j0", "j1"])


def test_every_preset_is_valid_and_within_joint_limits():
    presets = list_presets()
    # 17 sequences (12 of the paper, two heavy occlusions, one model mismatch, two with a
    # second camera) x 7 biases (none, constant, time-varying, ramp, random walks of 1, 3
    # and 6 deg/sqrt(s)).
    assert len(presets) == 119
    model = build_tracker_model(load_scenario("static/none").resolved_robot_config())
    names = model.robot_joint_names
    lower = model.plant.GetPositionLowerLimits()[:len(names)]
    upper = model.plant.GetPositionUpperLimits()[:len(names)]
    for name in presets:
        s = load_scenario(name, validate=False)
        validate_scenario(s, check_model=False)
        traj = make_joint_trajectory(s.trajectory, names, ROBOT_PROFILES["apollo.sdf"], s.seed)
        check_within_limits(traj.positions(np.arange(0.0, s.duration_s, 0.05)), lower, upper,
                            names)
    validate_scenario(load_scenario("occlusion/time-varying"))
    validate_scenario(load_scenario("occlusion-heavy/ramp"))
    validate_scenario(load_scenario("s-head-arm-mismatch/constant"))


def _plain_sinusoid(traj, t):
    """The sinusoid's formula joint by joint (what ``positions`` computes all at once)."""
    t = np.atleast_1d(np.asarray(t, float))
    q = np.tile(traj.home, (len(t), 1))
    for k, j in enumerate(traj.moved):
        period = traj.period_s * (1.0 + 0.17 * k)
        q[:, j] += traj.amplitude * np.sin(2 * np.pi * t / period + k * np.pi / 3)
    return q


@pytest.mark.parametrize("joints", [[], ["j0", "j2"], ["j1", "j1", "j2"]])
def test_sinusoid_equals_its_joint_by_joint_formula_bit_for_bit(joints):
    config = TrajectoryConfig(kind="sinusoid", joints=joints, amplitude_deg=23.0,
                              period_s=3.7, home_deg={"j1": 30.0})
    traj = make_joint_trajectory(config, NAMES, None, seed=0)
    times = np.concatenate([np.arange(0.0, 3.0, 1e-3),
                            np.random.default_rng(1).uniform(-5.0, 1e4, 3000)])
    for t in times[::7]:
        np.testing.assert_array_equal(traj.positions(t), _plain_sinusoid(traj, t))
    for count in (1, 2, 5, 8, 9, len(times)):
        np.testing.assert_array_equal(traj.positions(times[:count]),
                                      _plain_sinusoid(traj, times[:count]))
    traj.period_s = 1.3  # the cached periods follow a change
    np.testing.assert_array_equal(traj.positions(times), _plain_sinusoid(traj, times))


def _plain_free(traj, t):
    """The free motion's formula joint by joint, sum by sum (what ``positions`` computes
    for all moved joints at once)."""
    t = np.atleast_1d(np.asarray(t, float))
    q = np.tile(traj.home, (len(t), 1))
    for k, j in enumerate(traj.moved):
        for m in range(traj.freqs.shape[1]):
            q[:, j] += traj.amplitude * traj.weights[k, m] * np.sin(
                2 * np.pi * (t * traj.freqs[k, m]) + traj.phases[k, m])
    if traj.kind == "in-out-in" and traj.excursion_index >= 0:
        q[:, traj.excursion_index] += traj.excursion * smooth_window(t, *traj.excursion_window)
    return q


@pytest.mark.parametrize(("kind", "joints"), [("free", []), ("free", ["j0", "j2"]),
                                              ("free", ["j1", "j1", "j2"]),
                                              ("in-out-in", ["j0", "j1"])])
def test_free_motion_equals_its_joint_by_joint_formula(kind, joints):
    config = TrajectoryConfig(kind=kind, joints=joints, amplitude_deg=17.0, speed_scale=1.7,
                              excursion_joint="j2", excursion_start_s=1.0,
                              excursion_duration_s=2.0, excursion_ramp_s=0.5)
    traj = make_joint_trajectory(config, NAMES, None, seed=3)
    times = np.concatenate([np.arange(0.0, 5.0, 1e-3),
                            np.random.default_rng(2).uniform(-5.0, 1e3, 500)])
    for t in times[::97]:  # one time at a time, as the simulated encoders ask
        np.testing.assert_allclose(traj.positions(t), _plain_free(traj, t), rtol=0,
                                   atol=1e-15)  # the same sines, summed in another order
    np.testing.assert_allclose(traj.positions(times), _plain_free(traj, times), rtol=0,
                               atol=1e-15)


@pytest.mark.parametrize(("kind", "joints"), [
    ("sinusoid", []), ("sinusoid", ["j0", "j2"]), ("sinusoid", ["j1", "j1", "j2"]),
    ("free", []), ("free", ["j0", "j2"]), ("free", ["j1", "j1", "j2"]),
    ("in-out-in", ["j0", "j1"]), ("static", [])])
def test_position_at_one_time_equals_positions_bit_for_bit(kind, joints):
    config = TrajectoryConfig(kind=kind, joints=joints, amplitude_deg=19.0, period_s=2.9,
                              speed_scale=1.3, home_deg={"j1": 12.0}, excursion_joint="j2",
                              excursion_start_s=1.0, excursion_duration_s=2.0,
                              excursion_ramp_s=0.5)
    traj = make_joint_trajectory(config, NAMES, None, seed=4)
    times = np.concatenate([np.arange(0.0, 4.0, 1e-3),
                            np.random.default_rng(3).uniform(-5.0, 1e4, 2000)])
    for t in times:
        np.testing.assert_array_equal(traj.position_at(t), traj.positions(t)[0])
    traj.period_s = 1.1  # a change of the cached periods is followed here too
    np.testing.assert_array_equal(traj.position_at(0.37), traj.positions(0.37)[0])
