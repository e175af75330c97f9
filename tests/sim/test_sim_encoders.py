"""BiasedEncoders against the configured bias and noise statistics, rates and stamps."""

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource

from drake_tracker.sim.encoders import BiasedEncoders, sample_normals
from drake_tracker.sim.scenario.load import EncoderConfig

NAMES = ["a", "b", "c"]
TRUE_Q = np.array([0.3, -0.2, 1.0])


def run_encoders(config: EncoderConfig, duration_s: float, seed: int = 0,
                 biased=("a", "b")):
    """(stamps, readings, biases) of every sample in [0, duration_s]."""
    builder = DiagramBuilder()
    source = builder.AddSystem(ConstantVectorSource(TRUE_Q))
    enc = builder.AddSystem(BiasedEncoders(NAMES, config, seed, list(biased)))
    builder.Connect(source.get_output_port(), enc.get_input_port(0))
    diagram = builder.Build()
    sim = Simulator(diagram)
    ctx = enc.GetMyContextFromRoot(sim.get_mutable_context())
    h = 1.0 / config.rate_hz
    stamps, readings, biases = [], [], []
    for k in range(int(round(duration_s / h)) + 1):
        sim.AdvanceTo(k * h + 0.5 * h)
        stamps.append(enc.GetOutputPort("measurement_time").Eval(ctx)[0])
        readings.append(enc.GetOutputPort("measured_position").Eval(ctx).copy())
        biases.append(enc.GetOutputPort("bias").Eval(ctx).copy())
    return np.array(stamps), np.array(readings), np.array(biases)


def test_stamps_are_the_sample_times_at_the_configured_rate():
    config = EncoderConfig(rate_hz=250.0, noise_sigma_deg=0.0)
    stamps, _, _ = run_encoders(config, 0.4)
    np.testing.assert_allclose(stamps, np.arange(101) / 250.0, atol=1e-12)


def test_no_sample_before_time_zero():
    enc = BiasedEncoders(NAMES, EncoderConfig(), 0, [])
    ctx = enc.CreateDefaultContext()
    enc.get_input_port(0).FixValue(ctx, TRUE_Q)
    assert enc.GetOutputPort("measurement_time").Eval(ctx)[0] == -1.0


def test_constant_bias_and_white_noise_statistics():
    config = EncoderConfig(rate_hz=1000.0, bias="constant", constant_bias_deg=8.6,
                           noise_sigma_deg=0.05)
    _, readings, biases = run_encoders(config, 3.0)
    err = np.degrees(readings - TRUE_Q)
    # Biased joints a, b: mean 8.6 deg; unbiased c: 0. 3001 samples: the mean's standard
    # error is 0.05 / sqrt(3001) ~ 0.001 deg.
    np.testing.assert_allclose(err.mean(axis=0), [8.6, 8.6, 0.0], atol=0.005)
    np.testing.assert_allclose(err.std(axis=0), 0.05, rtol=0.06)
    np.testing.assert_allclose(np.degrees(biases), np.tile([8.6, 8.6, 0.0], (len(biases), 1)),
                               atol=1e-12)
    # Successive samples are independent (lag-1 correlation ~ N(0, 1/sqrt(3000))).
    for j in range(3):
        r = np.corrcoef(err[:-1, j], err[1:, j])[0, 1]
        assert abs(r) < 0.08, r


def test_step_bias_alternates_with_the_configured_amplitude():
    config = EncoderConfig(rate_hz=20.0, bias="steps", step_amplitude_deg=5.0,
                           step_period_s=2.0, step_transition_s=0.5, noise_sigma_deg=0.0)
    stamps, readings, biases = run_encoders(config, 6.5)
    deg = np.degrees(readings - TRUE_Q)
    np.testing.assert_allclose(deg, np.degrees(biases), atol=1e-9)
    at = {round(t, 6): row for t, row in zip(stamps, deg)}
    # Plateaus (away from the 0.5 s transitions centred on 2, 4, 6 s): joint a starts at
    # +5, joint b at -5, the sign flips every period; c is not biased.
    for t, sign in ((1.0, 1), (3.0, -1), (5.0, 1)):
        np.testing.assert_allclose(at[t], [5 * sign, -5 * sign, 0.0], atol=1e-9)
    # A jump reaches 10 deg and is smooth: within the transition the bias is in between.
    assert at[2.0][0] == pytest.approx(0.0, abs=1e-9)
    assert 0 < at[1.9][0] < 5 and -5 < at[2.1][0] < 0
    assert np.max(np.abs(np.diff(deg[:, 0]))) < 10 * (1 / 20) / 0.5 * np.pi / 2 + 1e-9


def test_random_walk_variance_grows_linearly_over_seeds():
    sigma = 2.0  # deg / sqrt(s)
    config = EncoderConfig(rate_hz=10.0, bias="random-walk",
                           random_walk_sigma_deg_per_sqrt_s=sigma, noise_sigma_deg=0.0)
    finals = []
    for seed in range(150):
        stamps, _, biases = run_encoders(config, 4.0, seed=seed)
        finals.append(np.degrees(biases[[10, 40]]))  # t = 1 s and t = 4 s
    b = np.array(finals)  # (seeds, 2 times, 3 joints)
    assert np.all(b[:, :, 2] == 0.0)
    biased = b[:, :, :2]
    var_1 = biased[:, 0].var()
    var_4 = biased[:, 1].var()
    inc = (biased[:, 1] - biased[:, 0]).var()
    # 300 values each: the variance estimate has a relative sd of about 8%.
    assert var_1 == pytest.approx(sigma**2 * 1.0, rel=0.3)
    assert var_4 == pytest.approx(sigma**2 * 4.0, rel=0.3)
    assert inc == pytest.approx(sigma**2 * 3.0, rel=0.3)
    assert abs(biased.mean()) < 3 * sigma * 2 / np.sqrt(300)


def test_quantization_rounds_readings():
    config = EncoderConfig(rate_hz=10.0, noise_sigma_deg=0.0, quantization_deg=0.5)
    _, readings, _ = run_encoders(config, 0.2, biased=())
    steps = np.degrees(readings) / 0.5
    np.testing.assert_allclose(steps, np.round(steps), atol=1e-9)
    expected = np.round(np.degrees(TRUE_Q) / 0.5) * 0.5
    np.testing.assert_allclose(np.degrees(readings), np.tile(expected, (len(readings), 1)),
                               atol=1e-9)


def test_counter_based_draws_do_not_overlap_between_indices():
    a = sample_normals(3, 10, 64)
    b = sample_normals(3, 11, 64)
    assert not np.any(np.isin(a, b))
    np.testing.assert_array_equal(a, sample_normals(3, 10, 64))


def test_unknown_biased_joint_is_rejected():
    with pytest.raises(ValueError, match="biased_joints"):
        BiasedEncoders(NAMES, EncoderConfig(), 0, ["nope"])


def test_counter_normals_draw_exactly_what_sample_normals_draws():
    from drake_tracker.sim.streams import CounterNormals

    for seed, stream in ((0, 0), (3, 0), (11, 7), (2**63, 0)):
        draw = CounterNormals(seed, stream)
        for index in (0, 1, 2, 999, 123_456, 2**32 + 5, 2**64 - 1):
            for size in (1, 14, 257):
                np.testing.assert_array_equal(draw(index, size),
                                              sample_normals(seed, index, size, stream))


@pytest.mark.parametrize("bias", ["constant", "steps", "random-walk"])
def test_readings_are_exactly_the_plain_formula(bias):
    """Every reading is quantize(true + bias + sigma * sample_normals(seed, k)[:n]), its
    bias the model's next() with the rest of those draws (the system writes them straight
    into its state and draws through CounterNormals)."""
    from drake_tracker.sim.bias import JointBiasModel
    from drake_tracker.sim.encoders import quantize

    config = EncoderConfig(rate_hz=100.0, bias=bias, constant_bias_deg=8.6,
                           quantization_deg=0.01, step_period_s=0.05)
    stamps, readings, biases = run_encoders(config, 0.3, seed=4)
    model = JointBiasModel(config, NAMES, ["a", "b"])
    previous, n = np.zeros(3), len(NAMES)
    for k, t in enumerate(stamps):
        draws = sample_normals(4, k, 2 * n)
        bias_k = model.next(previous, t, None if k == 0 else t - stamps[k - 1], draws[n:])
        expected = quantize(TRUE_Q + bias_k + np.radians(config.noise_sigma_deg) * draws[:n],
                            np.radians(config.quantization_deg))
        np.testing.assert_array_equal(biases[k], bias_k)
        np.testing.assert_array_equal(readings[k], expected)
        previous = bias_k
