"""The file cases of ``fault_survey.py``: parameter files field by field, scenario files
and recordings. Each case is (name, path-writing function, loader, keyword, valid):
the loader must raise a clear error naming ``keyword``, or load when ``valid``."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from drake_tracker.io.recording import RecordedRun
from drake_tracker.params.loading import load_tracker_params
from drake_tracker.sim.scenario.load import load_scenario

#: (YAML path of a TrackerParams field, bad values): each value written alone.
PARAM_FIELDS = {
    "kalman.robot_joints.encoder_noise_std_rad": [".nan", "-1.0", "0.0", "x", "1.0e+200"],
    "kalman.robot_joints.angle_process_std_rad_per_sqrt_s": [".inf", "1.0e+200"],
    "kalman.robot_joints.bias_decay_per_s": ["1.5", "0.0"],
    "kalman.robot_joints.bias_jump_rate_per_s": ["-0.1"],
    "kalman.virtual_joints.initial_bias_std_rad": [".nan"],
    "image.num_particles": ["0", "-5", "1.5", "many"],
    "image.annealing_betas": ["0.5", "[]", "[0.5]", "[1.0, 0.5]", "[2.0]"],
    "image.likelihood.max_depth_m": [".inf", "0.0"],
    "image.likelihood.occluder_rate_per_m": [".inf"],
    "image.likelihood.depth_noise_std_m": [".inf", "0.0"],
    "image.likelihood.tail_weight": ["1.5"],
    "image.likelihood.occlusion_probability": ["1.0"],
    "image.renderer": ["vulkan"],
    "image.seed": ["-1"],
    "image.max_kl": ["0.0"],
    "image.near_m": ["7.0"],
    "image.image_time_offset_s": [".nan"],
    "image.min_image_interval_s": ["-0.1", ".nan"],
    "image.update_latency_s": ["-0.01", ".inf"],
    "health.max_see_through": ["2.0"],
    "buffer_horizon_s": [".inf", "0.0", "-1.0"],
    "max_interpolation_gap_s": ["-1.0"],
    "timestamps.reanchor_after_samples": ["1"],
    "timestamps.min_future_jump_s": [".inf"],
    "initial_positions_rad": ["{arm_joint_1: .nan}"],
}

#: (name, YAML text, keyword) of TrackerParams files that are bad as a whole.
PARAM_FILES = [
    ("params: unknown field", "no_such_field: 1\n", "no_such_field"),
    ("params: YAML syntax error", "image: [\n", ""),
    ("params: a list at the root", "- 1\n- 2\n", "dict"),
    ("params: a scalar at the root", "3\n", ""),
]

#: Files that are valid.
PARAM_VALID = [("params: empty file", ""), ("params: only a comment", "# nothing\n")]

SCENARIO_FILES = [
    ("scenario: duration_s: long", "duration_s: long\n", "duration_s"),
    ("scenario: duration_s: -1", "duration_s: -1.0\n", "duration_s"),
    ("scenario: duration_s: .nan", "duration_s: .nan\n", "duration_s"),
    ("scenario: preset: 3", "preset: 3\n", "preset"),
    ("scenario: unknown preset", "preset: nope/none\n", "preset"),
    ("scenario: camera.rate_hz: 0", "camera:\n  rate_hz: 0.0\n", "rate_hz"),
    ("scenario: camera.rate_hz: [30]", "camera:\n  rate_hz: [30]\n", "rate_hz"),
    ("scenario: encoders.rate_hz: -1", "encoders:\n  rate_hz: -1.0\n", "rate_hz"),
    ("scenario: trajectory.kind: zigzag", "trajectory:\n  kind: zigzag\n", "kind"),
    ("scenario: robot: nope", "robot: nope\n", "robot"),
    ("scenario: encoders.bias: weird", "encoders:\n  bias: weird\n", "bias"),
    ("scenario: unknown field", "no_such_field: 1\n", "no_such_field"),
    ("scenario: a list at the root", "- 1\n", "mapping"),
    ("scenario: YAML syntax error", "camera: [\n", ""),
]
SCENARIO_VALID = [("scenario: empty file", ""), ("scenario: a preset only",
                                                  "preset: static/none\n")]


def _yaml_for(field: str, value: str) -> str:
    parts = field.split(".")
    lines = [f"{'  ' * i}{p}:" for i, p in enumerate(parts[:-1])]
    lines.append(f"{'  ' * (len(parts) - 1)}{parts[-1]}: {value}")
    return "\n".join(lines) + "\n"


def file_cases(folder: Path, run: RecordedRun) -> list:
    """(name, callable loading the bad file, keyword or None when the file is valid)."""
    cases = []

    def text_case(name, text, loader, keyword, suffix=".yaml"):
        path = folder / f"case{len(cases)}{suffix}"
        path.write_text(text)
        cases.append((name, lambda: loader(path), keyword))

    for field, values in PARAM_FIELDS.items():
        for value in values:
            text_case(f"params: {field}: {value}", _yaml_for(field, value),
                      load_tracker_params, field.split(".")[-1])
    for name, text, keyword in PARAM_FILES:
        text_case(name, text, load_tracker_params, keyword)
    for name, text in PARAM_VALID:
        text_case(name, text, load_tracker_params, None)
    for name, text, keyword in SCENARIO_FILES:
        text_case(name, text, load_scenario, keyword)
    for name, text in SCENARIO_VALID:
        text_case(name, text, load_scenario, None)
    cases.append(("params: missing file", lambda: load_tracker_params(folder / "none.yaml"),
                  "does not exist"))
    cases.append(("scenario: missing file", lambda: load_scenario(folder / "none.yaml"),
                  "does not exist"))

    good = run.save(folder / "good.npz")
    text_case("recording: a text file", "not an archive", RecordedRun.load, "not a", ".npz")
    truncated = folder / "truncated.npz"
    truncated.write_bytes(good.read_bytes()[: good.stat().st_size // 2])
    cases.append(("recording: truncated", lambda: RecordedRun.load(truncated), "not a"))
    keys = folder / "keys.npz"
    np.savez(keys, format_version=np.array(1))
    cases.append(("recording: missing arrays", lambda: RecordedRun.load(keys), "not a"))
    version = folder / "version.npz"
    with np.load(good) as data:
        np.savez(version, **{**dict(data), "format_version": np.array(7)})
    cases.append(("recording: format_version 7", lambda: RecordedRun.load(version),
                  "format_version"))
    cases.append(("recording: missing file", lambda: RecordedRun.load(folder / "none.npz"),
                  "does not exist"))
    return cases
