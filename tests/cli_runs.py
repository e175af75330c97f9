"""The command line run in the test's own process, and the check of its one-line errors
(shared by the tests of the commands: ``apps/test_cli.py``, ``io/test_lcm_log.py``,
``io/test_multicamera_bags.py``)."""

from drake_tracker.cli.main import main


def run_cli(argv, capsys):
    """(exit code, stdout, stderr) of ``drake-tracker ARGV`` run in this process."""
    try:
        code = main(argv)
    except SystemExit as stop:
        code = stop.code
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def assert_one_line_error(code, err, *fragments):
    assert code == 2, err
    assert "Traceback" not in err
    lines = err.strip().splitlines()
    assert len(lines) == 1, lines
    for fragment in fragments:
        assert fragment in lines[0], lines[0]
