"""Bias profiles against their formulas (ramp, listed steps, constant), the random walk's
statistics over seeds, per-joint profiles in the encoder system, the ramp preset."""

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource

from drake_tracker.sim.bias import JointBiasModel, listed_steps_bias, profile_bias, ramp_bias
from drake_tracker.sim.encoders import BiasedEncoders
from drake_tracker.sim.scenario.load import BiasProfile, EncoderConfig, load_scenario
from drake_tracker.sim.streams import sample_normals

NAMES = ["a", "b", "c", "d"]


def encoder_biases(config: EncoderConfig, biased: list[str], seed: int = 0,
                   duration_s: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """(sample times, biases (T, 4)) of a BiasedEncoders system run for ``duration_s``."""
    builder = DiagramBuilder()
    source = builder.AddSystem(ConstantVectorSource(np.zeros(len(NAMES))))
    encoders = builder.AddSystem(BiasedEncoders(NAMES, config, seed, biased))
    builder.Connect(source.get_output_port(), encoders.get_input_port(0))
    simulator = Simulator(builder.Build())
    context = encoders.GetMyContextFromRoot(simulator.get_mutable_context())
    times, biases = [], []
    period = 1.0 / config.rate_hz
    for k in range(int(round(duration_s / period)) + 1):
        simulator.AdvanceTo(k * period + 0.5 * period)
        times.append(encoders.GetOutputPort("measurement_time").Eval(context)[0])
        biases.append(encoders.GetOutputPort("bias").Eval(context).copy())
    return np.array(times), np.array(biases)


def test_ramp_matches_its_formula():
    t = np.linspace(-1.0, 15.0, 321)
    profile = BiasProfile(kind="ramp", ramp_from_deg=-2.0, value_deg=6.0, ramp_start_s=1.0,
                          ramp_duration_s=8.0)
    expected = np.where(t < 1.0, -2.0, np.where(t > 9.0, 6.0, -2.0 + 8.0 * (t - 1.0) / 8.0))
    np.testing.assert_allclose(profile_bias(profile, t), np.radians(expected), atol=1e-12)
    assert ramp_bias(np.array([0.0, 1.0]), 0.0, 1.0, 0.5, 0.0).tolist() == [0.0, 1.0]


def test_listed_steps_hold_their_values_and_change_smoothly():
    profile = BiasProfile(kind="steps", step_times_s=[2.0, 5.0], step_values_deg=[4.0, -3.0],
                          step_transition_s=1.0)
    b = np.degrees(profile_bias(profile, np.array([0.0, 1.49, 2.0, 2.51, 4.4, 5.0, 6.0])))
    np.testing.assert_allclose(b, [0.0, 0.0, 2.0, 4.0, 4.0, 0.5, -3.0], atol=1e-9)
    # Between plateaus the half-cosine: at a quarter of the transition, 1 - cos(pi/4) over 2.
    quarter = listed_steps_bias(np.array([1.75]), [2.0], [1.0], 1.0)[0]
    assert quarter == pytest.approx(0.5 - 0.5 * np.cos(np.pi / 4))


def test_constant_and_ramp_of_the_encoder_config_and_per_joint_profiles():
    config = EncoderConfig(rate_hz=50.0, bias="ramp", constant_bias_deg=8.6,
                           ramp_start_s=0.2, ramp_duration_s=0.5, noise_sigma_deg=0.0,
                           bias_profiles={"d": BiasProfile(kind="constant", value_deg=-1.5)})
    times, biases = encoder_biases(config, ["a", "c"])
    ramp = np.radians(8.6) * np.clip((times - 0.2) / 0.5, 0.0, 1.0)
    np.testing.assert_allclose(biases[:, 0], ramp, atol=1e-12)
    np.testing.assert_allclose(biases[:, 2], ramp, atol=1e-12)
    np.testing.assert_array_equal(biases[:, 1], 0.0)  # not biased, no profile
    np.testing.assert_allclose(biases[:, 3], np.radians(-1.5), atol=1e-15)


def test_random_walk_statistics_over_seeds():
    # Joint b: 2 deg/sqrt(s) with a drift of 3 deg/s; after t the bias is N(3 t, 4 t) deg.
    config = EncoderConfig(rate_hz=100.0, bias_profiles={
        "b": BiasProfile(kind="random-walk", random_walk_sigma_deg_per_sqrt_s=2.0,
                         random_walk_drift_deg_per_s=3.0)})
    model = JointBiasModel(config, NAMES, [])
    seeds, steps, dt = 400, 100, 0.01
    finals = []
    for seed in range(seeds):
        bias, previous_t = np.zeros(4), None
        for k in range(steps + 1):
            t = k * dt
            draws = sample_normals(seed, k, 8)[4:]
            bias = model.next(bias, t, None if previous_t is None else t - previous_t, draws)
            previous_t = t
        finals.append(np.degrees(bias))
    finals = np.array(finals)
    t_end = steps * dt
    assert np.all(finals[:, [0, 2, 3]] == 0.0)
    mean, var = finals[:, 1].mean(), finals[:, 1].var(ddof=1)
    # 400 seeds: the mean's standard error is 0.1 deg, the variance's about 7 %.
    assert mean == pytest.approx(3.0 * t_end, abs=0.35)
    assert var == pytest.approx(4.0 * t_end, rel=0.25)
    # The system draws the same walk as the model, seed for seed.
    _, biases = encoder_biases(config, [], seed=7, duration_s=0.2)
    bias, previous_t = np.zeros(4), None
    for k in range(21):
        t = k * 0.01
        bias = model.next(bias, t, None if previous_t is None else t - previous_t,
                          sample_normals(7, k, 8)[4:])
        previous_t = t
        np.testing.assert_allclose(biases[k], bias, atol=1e-15)


def test_ramp_preset_and_profile_errors():
    s = load_scenario("s-full-arm/ramp")
    e = s.encoders
    assert (e.bias, e.constant_bias_deg, e.ramp_start_s, e.ramp_duration_s) == (
        "ramp", 8.6, 0.0, 10.0)
    e.bias_profiles = {"arm_joint_1": BiasProfile(kind="steps", step_times_s=[1.0, 1.2],
                                                  step_values_deg=[1.0, 2.0])}
    from drake_tracker.sim.scenario.load import validate_scenario

    with pytest.raises(ValueError, match=r"bias_profiles\[arm_joint_1\]\.step_times_s"):
        validate_scenario(s, check_model=False)
    e.bias_profiles = {"arm_joint_1": BiasProfile(kind="wobble")}
    with pytest.raises(ValueError, match=r"bias_profiles\[arm_joint_1\]\.kind"):
        validate_scenario(s, check_model=False)
    e.bias_profiles = {"elbow": BiasProfile()}
    with pytest.raises(ValueError, match=r"encoders\.bias_profiles"):
        validate_scenario(s)


@pytest.mark.parametrize("bias", ["none", "constant", "random-walk", "steps", "ramp"])
def test_a_time_independent_bias_computed_once_equals_the_formula(bias):
    profiles = {"c": BiasProfile(kind="constant", value_deg=-3.0),
                "d": BiasProfile(kind="random-walk")}
    config = EncoderConfig(bias=bias, constant_bias_deg=8.6, bias_profiles=profiles)
    model = JointBiasModel(config, NAMES, ["a", "b"])
    for t in (0.0, 0.37, 2.5, 11.0):
        fixed = model.deterministic(t)
        np.testing.assert_array_equal(fixed, model._deterministic(t))
        fixed[:] = 99.0  # a copy: the next sample is not affected
        assert not np.array_equal(model.deterministic(t), fixed)


@pytest.mark.parametrize("rate", [1, 3, 6])
def test_random_walk_presets_drift_at_their_rate(rate):
    """``s-full-arm/random-walk-R``: every arm joint's bias a random walk of R deg/sqrt(s)
    from 0; over 300 seeds of one joint after 1 s, variance R^2 (std. error about 8 %)."""
    s = load_scenario(f"s-full-arm/random-walk-{rate}")
    assert (s.encoders.bias, s.encoders.random_walk_sigma_deg_per_sqrt_s) == (
        "random-walk", float(rate))
    names = ["j0", "j1"]
    model = JointBiasModel(s.encoders, names, ["j1"])
    finals = []
    for seed in range(300):
        bias, previous_t = np.zeros(2), None
        for k in range(11):
            t = 0.1 * k
            bias = model.next(bias, t, None if previous_t is None else t - previous_t,
                              sample_normals(seed, k, 4)[2:])
            previous_t = t
        finals.append(np.degrees(bias))
    finals = np.array(finals)
    assert np.all(finals[:, 0] == 0.0)  # an unbiased joint stays at 0
    assert finals[:, 1].var(ddof=1) == pytest.approx(rate ** 2, rel=0.3)
