"""One-line descriptions of the scenario presets, for ``drake-tracker scenarios``."""

from __future__ import annotations

from drake_tracker.sim.scenario.load import Scenario, list_presets, load_scenario


def describe_motion(scenario: Scenario) -> str:
    """The commanded motion in a few words, e.g. ``sinusoid ±15°, 7 joints``."""
    t = scenario.trajectory
    joints = f"{len(t.joints)} joints" if t.joints else "the arm"
    if t.kind == "static":
        text = "static"
    elif t.kind == "sinusoid":
        text = f"sinusoid ±{t.amplitude_deg:g}°, {joints}"
    else:
        text = f"free motion ±{t.amplitude_deg:g}°, {joints}"
        if t.speed_scale != 1.0:
            text += f", {t.speed_scale:g}x faster"
    if t.kind == "in-out-in":
        text += (f"; out of view {t.excursion_start_s:g}-"
                 f"{t.excursion_start_s + 2 * t.excursion_ramp_s + t.excursion_duration_s:g} s")
    if scenario.occluder.enabled:
        text += (f"; a box occludes the arm {scenario.occluder.start_s:g}-"
                 f"{scenario.occluder.end_s:g} s")
    for occluder in scenario.occluders:
        until = f"-{occluder.leave_s:g} s" if occluder.leave_s < 1e300 else " s to the end"
        text += f"; a {occluder.shape} occludes {occluder.enter_s:g}{until}"
    if scenario.model_mismatch.enabled:
        text += "; the world robot is not the model"
    return text


def describe_bias(scenario: Scenario) -> str:
    """The encoder bias in a few words, e.g. ``8.6° constant bias``."""
    e = scenario.encoders
    if e.bias == "none":
        return "no bias"
    if e.bias == "constant":
        return f"{e.constant_bias_deg:g}° constant bias"
    if e.bias == "steps":
        return f"±{e.step_amplitude_deg:g}° bias steps every {e.step_period_s:g} s"
    if e.bias == "ramp":
        return f"bias ramp 0 to {e.constant_bias_deg:g}° over {e.ramp_duration_s:g} s"
    return f"random-walk bias {e.random_walk_sigma_deg_per_sqrt_s:g}°/√s"


def preset_lines() -> list[str]:
    """One line per preset: name, duration, motion, bias."""
    names = list_presets()
    width = max(len(n) for n in names)
    lines = []
    for name in names:
        s = load_scenario(name, validate=False)
        lines.append(f"{name:<{width}}  {s.duration_s:>4g} s  {describe_motion(s)}; "
                     f"{describe_bias(s)}")
    return lines
