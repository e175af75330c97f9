"""The command line as a user meets it: one-line errors with exit code 2 and no
traceback, nothing written before the arguments are checked, and the discovery
commands (--version, scenarios, params). No simulation runs here (tests/apps/test_demo.py
runs the one short demo)."""


import pytest
from cli_runs import assert_one_line_error, run_cli
from repo_root import ROOT

from drake_tracker.cli.args import UsageError, scenario_name
from drake_tracker.cli.main import main
from drake_tracker.params.loading import load_tracker_params
from drake_tracker.params.tracker_params import TrackerParams
from drake_tracker.sim.scenario.load import ALL_SEQUENCES, BIAS_VARIANTS, list_presets

EXAMPLES = ROOT / "examples"


def test_unknown_scenario_is_one_line_and_writes_nothing(tmp_path, capsys):
    out = tmp_path / "demo"
    code, _, err = run_cli(["demo", "--scenario", "nosuch", "--out", str(out)], capsys)
    assert_one_line_error(code, err, "unknown scenario 'nosuch'", "drake-tracker scenarios",
                          "constant")
    # Not the 36 preset names on one line.
    assert sum(name in err for name in list_presets()) < 3
    assert not out.exists()


def test_a_near_miss_suggests_the_close_names(tmp_path, capsys):
    code, _, err = run_cli(["demo", "--scenario", "s-ful-arm", "--out", str(tmp_path / "d")],
                           capsys)
    assert_one_line_error(code, err, "did you mean", "s-full-arm")


def test_an_unknown_bias_variant_lists_the_variants(tmp_path, capsys):
    code, _, err = run_cli(["record", "--scenario", "arm/sometimes",
                            "--out", str(tmp_path / "r.npz")], capsys)
    assert_one_line_error(code, err, "unknown bias variant 'sometimes'", *BIAS_VARIANTS)


def test_a_bare_sequence_name_means_its_constant_bias_variant():
    for sequence in ALL_SEQUENCES:
        assert scenario_name(sequence) == f"{sequence}/constant"
    assert scenario_name("occlusion/none") == "occlusion/none"
    with pytest.raises(UsageError):
        scenario_name("no-such-sequence")


def test_a_missing_or_broken_recorded_run_is_one_line(tmp_path, capsys):
    code, _, err = run_cli(["track", "--run", str(tmp_path / "missing.npz")], capsys)
    assert_one_line_error(code, err, "missing.npz", "does not exist", "drake-tracker record")
    broken = tmp_path / "broken.npz"
    broken.write_bytes(b"not a zip file")
    code, _, err = run_cli(["track", "--run", str(broken)], capsys)
    assert_one_line_error(code, err, "broken.npz", "is not a recorded run")


@pytest.mark.parametrize("content, fragment", [
    (None, "does not exist"),
    ("kalman: [1, 2]\n", "params.yaml"),
    ("image:\n  num_particles: 0\n", "num_particles"),
    ("no_such_field: 3\n", "no_such_field"),
])
def test_a_missing_or_invalid_params_file_is_one_line(tmp_path, capsys, content, fragment):
    path = tmp_path / "params.yaml"
    if content is not None:
        path.write_text(content)
    out = tmp_path / "demo"
    code, _, err = run_cli(["demo", "--params", str(path), "--out", str(out)], capsys)
    assert_one_line_error(code, err, fragment)
    assert not out.exists()


def test_params_naming_a_joint_the_robot_lacks_is_one_line(tmp_path, capsys):
    path = tmp_path / "params.yaml"
    path.write_text("kalman:\n  overrides:\n    elbow_of_nobody: {has_bias: false}\n")
    out = tmp_path / "demo"
    code, _, err = run_cli(["demo", "--params", str(path), "--out", str(out),
                            "--duration", "1"], capsys)
    assert_one_line_error(code, err, "elbow_of_nobody")
    assert not out.exists()


@pytest.mark.parametrize("duration", ["-1", "0", "nan", "soon"])
def test_a_bad_duration_is_refused_before_anything_is_written(tmp_path, capsys, duration):
    out = tmp_path / "demo"
    code, _, err = run_cli(["demo", "--duration", duration, "--out", str(out)], capsys)
    assert code == 2 and "Traceback" not in err
    assert "argument --duration" in err.strip().splitlines()[-1]
    assert not out.exists()


def test_an_unknown_option_prints_the_subcommands_usage(capsys):
    code, _, err = run_cli(["demo", "--bogus"], capsys)
    assert code == 2
    assert err.startswith("usage: drake-tracker demo")
    last = err.strip().splitlines()[-1]
    assert last == "drake-tracker demo: error: unrecognized arguments: --bogus"


def test_record_needs_an_npz_output(tmp_path, capsys):
    code, _, err = run_cli(["record", "--out", str(tmp_path / "run.txt")], capsys)
    assert_one_line_error(code, err, "must end with .npz")
    assert not (tmp_path / "run.txt").exists()


def test_debug_shows_the_traceback(tmp_path):
    with pytest.raises(UsageError, match="unknown scenario"):
        main(["demo", "--scenario", "nosuch", "--out", str(tmp_path / "d"), "--debug"])
    with pytest.raises(UsageError, match="unknown scenario"):
        main(["--debug", "demo", "--scenario", "nosuch", "--out", str(tmp_path / "d")])


def test_version(capsys):
    from drake_tracker import __version__

    code, out, _ = run_cli(["--version"], capsys)
    assert code == 0
    assert out.startswith(f"drake-tracker {__version__} (drake ")


def test_scenarios_lists_every_preset_on_its_own_line(capsys):
    code, out, _ = run_cli(["scenarios"], capsys)
    assert code == 0
    lines = out.splitlines()
    for name in list_presets():
        matching = [line for line in lines if line.split()[0] == name]
        assert len(matching) == 1, name
    occlusion = next(line for line in lines if line.startswith("occlusion/time-varying "))
    assert "occludes" in occlusion and "bias steps" in occlusion


def test_params_defaults_round_trip_through_params(tmp_path, capsys):
    code, out, _ = run_cli(["params", "--defaults"], capsys)
    assert code == 0
    path = tmp_path / "defaults.yaml"
    path.write_text(out)
    assert load_tracker_params(path) == TrackerParams()
    code, again, _ = run_cli(["params", str(path)], capsys)
    assert code == 0 and again == out


def test_the_example_params_file_loads_and_changes_nothing_it_names(capsys):
    path = EXAMPLES / "params.yaml"
    params = load_tracker_params(path)
    assert path.read_text().count("#") > 20  # commented
    # Its values are the defaults of the fields it lists.
    assert params.image.num_particles == TrackerParams().image.num_particles
    code, out, _ = run_cli(["params", str(path)], capsys)
    assert code == 0 and "num_particles" in out


@pytest.mark.parametrize("command", ["demo", "record", "track", "bench", "evaluate",
                                     "scenarios", "params"])
def test_every_command_has_help(capsys, command):
    code, out, _ = run_cli([command, "--help"], capsys)
    assert code == 0
    assert out.startswith(f"usage: drake-tracker {command}")
    assert "--debug" in out


def test_the_top_level_help_is_for_users(capsys):
    code, out, _ = run_cli(["--help"], capsys)
    assert code == 0
    assert "only parses" not in out
    for command in ("demo", "record", "track", "evaluate", "scenarios", "params"):
        assert command in out
    code, out, _ = run_cli(["record", "--help"], capsys)
    assert "SEQUENCE/BIAS" in out


def test_a_missing_graphviz_is_a_one_line_note(tmp_path, capsys, monkeypatch):
    import shutil

    from drake_tracker.demo.run import write_diagram

    monkeypatch.setattr(shutil, "which", lambda name: None)
    assert write_diagram("digraph {}", tmp_path) is None
    err = capsys.readouterr().err
    assert (tmp_path / "diagram.dot").read_text() == "digraph {}"
    assert len(err.strip().splitlines()) == 1 and "Graphviz" in err and "diagram.dot" in err


def test_a_command_stopping_with_a_message_is_a_one_line_error(tmp_path, capsys):
    out = tmp_path / "evaluate"
    code, _, err = run_cli(["evaluate", "--quick", "--methods", "magic", "--out", str(out)],
                           capsys)
    assert_one_line_error(code, err, "drake-tracker evaluate: error:", "unknown method 'magic'")
    assert not out.exists()
