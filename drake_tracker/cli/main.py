"""The ``drake-tracker`` command line: argument parsing and the common error handling.

Each subcommand's work lives in its own module. Arguments are checked here, before any
work starts or any file is written: a mistake prints one line (exit code 2, no
traceback; ``--debug`` shows it).
"""

from __future__ import annotations

import argparse
import sys
import textwrap
from pathlib import Path

from drake_tracker.cli.args import (
    PARAMS_HELP,
    SCENARIO_HELP,
    UsageError,
    check_out_dir,
    check_params_for_model,
    load_params_arg,
    load_servo_config_arg,
    positive_seconds,
    resolve_scenario,
)
from drake_tracker.cli.io_commands import add_calibrate, add_record, add_track

DESCRIPTION = """\
Track a robot arm from its joint encoders and a depth camera, on Drake.

Start with 'drake-tracker demo --duration 3' (about a minute); each command has
its own --help."""


class _CommandParser(argparse.ArgumentParser):
    """A subcommand's parser: examples kept as written, ``--debug``, and itself in the
    parsed namespace (so errors print this command's usage)."""

    def __init__(self, **kwargs):
        kwargs.setdefault("formatter_class", argparse.RawDescriptionHelpFormatter)
        if kwargs.get("description"):
            kwargs["description"] = textwrap.fill(kwargs["description"], 79)
        super().__init__(**kwargs)
        self.add_argument("--debug", action="store_true", default=argparse.SUPPRESS,
                          help="show the full traceback of an error")
        self.set_defaults(_parser=self)


class _MessageExit(SystemExit):
    """Exit code 2, keeping the message for ``str()`` (it was printed already)."""

    def __init__(self, message: str):
        super().__init__(2)
        self.message = message

    def __str__(self) -> str:
        return self.message


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    from drake_tracker import __version__

    try:
        drake = version("drake")
    except PackageNotFoundError:
        drake = "unknown"
    return f"drake-tracker {__version__} (drake {drake})"


def _add_demo(sub) -> None:
    p = sub.add_parser(
        "demo", help="simulate a scenario, track it in the Diagram, and report the errors",
        description="Simulates a scenario with the tracker inside the Drake Diagram, prints "
                    "the hand-pose error percentiles of the encoders alone and of the "
                    "tracker, and writes report.json, errors.png, meshcat.html and "
                    "diagram.dot (diagram.png with Graphviz) to --out.",
        epilog="examples:\n  drake-tracker demo --duration 3\n"
               "  drake-tracker demo --scenario occlusion/constant --out out/occlusion")
    p.add_argument("--scenario", default="s-full-arm/constant", help=SCENARIO_HELP)
    p.add_argument("--out", default="out/demo", help="output folder (default: %(default)s)")
    p.add_argument("--duration", type=positive_seconds, default=None, metavar="SECONDS",
                   help="simulate this long instead of the scenario's duration")
    p.add_argument("--params", default=None, metavar="YAML", help=PARAMS_HELP)

    def run(args):
        scenario = resolve_scenario(args.scenario)
        params = load_params_arg(args.params)
        check_out_dir(args.out)
        if args.params:
            from drake_tracker.robot.model import build_tracker_model

            model = build_tracker_model(scenario.resolved_robot_config())
            check_params_for_model(params, model, f"parameter file '{args.params}'")
        from drake_tracker.demo.run import run_demo

        return run_demo(args, scenario=scenario, params=params)

    p.set_defaults(func=run)


def _add_bench(sub) -> None:
    p = sub.add_parser(
        "bench", help="benchmark the tracker's hot paths",
        description="Measures image updates per second, the batched renderer against "
                    "Drake's RenderEngineVtk, and the Kalman bank and re-filtering steps; "
                    "writes bench.json to --out.")
    p.add_argument("--out", default="out/bench",
                   help="folder for bench.json (default: %(default)s)")
    p.add_argument("--quick", action="store_true", help="fewer repetitions")
    p.add_argument("--only", choices=["readings", "cameras", "decision"], default=None,
                   help="run one part alone: 'readings', what each joint reading costs "
                        "in a Diagram (bench.json then holds reading_path only); "
                        "'cameras', an image update's cost with one camera at 30 Hz and "
                        "two at 15 Hz (bench.json then holds cameras only); 'decision', "
                        "the per-image decision's time beside the image update's "
                        "(bench.json then holds decision only)")

    def run(args):
        check_out_dir(args.out)
        from drake_tracker.bench.run import run_bench

        return run_bench(args)

    p.set_defaults(func=run)


def _add_scenarios(sub) -> None:
    p = sub.add_parser(
        "scenarios", help="list the scenario presets, one line each",
        description="Lists the presets that --scenario accepts: name, duration, motion, "
                    "encoder bias. Every preset also has the camera's 2 cm / 2.6 deg "
                    "mounting error.")

    def run(args):
        from drake_tracker.cli.listing import preset_lines

        print("\n".join(preset_lines()))
        print("A bare SEQUENCE means SEQUENCE/constant. A YAML file of\n"
              "drake_tracker.sim.scenario.load.Scenario also works; it may start with "
              "'preset: NAME'.")
        return 0

    p.set_defaults(func=run)


def _add_params(sub) -> None:
    p = sub.add_parser(
        "params", help="print the tracker parameters as YAML (defaults, or a file's)",
        description="Prints tracker parameters as YAML that --params accepts: the "
                    "defaults, or the values a parameter file gives (after checking it).",
        epilog="examples:\n  drake-tracker params --defaults > my_params.yaml\n"
               "  drake-tracker params examples/params.yaml")
    which = p.add_mutually_exclusive_group(required=True)
    which.add_argument("--defaults", action="store_true", help="the default parameters")
    which.add_argument("file", nargs="?", metavar="YAML",
                       help="a parameter file to check and print with the defaults filled in")

    def run(args):
        from drake_tracker.params.loading import tracker_params_to_yaml

        print(tracker_params_to_yaml(load_params_arg(None if args.defaults else args.file)),
              end="")
        return 0

    p.set_defaults(func=run)


def _add_evaluate(sub) -> None:
    p = sub.add_parser(
        "evaluate", help="the paper's protocol: sequences x biases x seeds x methods",
        description="Runs the four methods on the simulated sequences x bias variants x "
                    "seeds, resumably: each finished task's result is kept in --out, and "
                    "the same command (on either executor) runs only the rest. Ctrl-C or "
                    "SIGTERM stops the workers. Writes summary.csv (percentiles, median "
                    "over seeds, worst seed), errors.csv, failures.json, protocol.json "
                    "and figures.",
        epilog="examples:\n  drake-tracker evaluate --quick --out out/quick\n"
               "  drake-tracker evaluate --quick --sequences s-full-arm --seeds 1 "
               "--duration 3 --out out/slice\n"
               "  drake-tracker evaluate --executor ray --address auto --out out/full")
    p.add_argument("--out", default="out/evaluate", help="output folder (resumable)")
    p.add_argument("--quick", action="store_true",
                   help="10 s runs of five kinds of sequence x three biases x 3 seeds")
    p.add_argument("--seeds", type=int, default=None,
                   help="seeds per case; each seeds the simulation and the tracker "
                        "(default: 3 quick, 10 full)")
    p.add_argument("--sequences", default=None,
                   help="comma-separated subset of the sequences (default: the mode's all)")
    p.add_argument("--methods", default=None,
                   help="comma-separated subset of the methods (default: all four)")
    p.add_argument("--duration", type=float, default=None, metavar="SECONDS",
                   help="shorten every run to this (a slice, e.g. to measure the cost)")
    p.add_argument("--executor", choices=("local", "ray"), default="local",
                   help="local: a process pool; ray: a Ray cluster (pip install "
                        "'drake_tracker[cluster]'), see the README (default: %(default)s)")
    p.add_argument("--address", default=None,
                   help="with --executor ray: a running cluster ('auto' or HOST:6379); "
                        "default: start a local Ray instance for this run")
    p.add_argument("--workers", type=int, default=2,
                   help="local processes, or CPUs of a local Ray instance (default: "
                        "%(default)s)")
    p.add_argument("--settle-s", type=float, default=5.0,
                   help="the summary and box plots use errors from this time on (s, "
                        "default %(default)s); errors.csv keeps every sample")
    p.add_argument("--params", default=None,
                   help="tracker parameters YAML the methods start from (default: defaults); "
                        "use a new --out folder per parameter file (results are resumed)")

    def run(args):
        from drake_tracker.evaluation.run import run_evaluate

        return run_evaluate(args)

    p.set_defaults(func=run)


def _add_compare(sub) -> None:
    p = sub.add_parser(
        "compare", help="compare two evaluations cell by cell, pooled over folders",
        description="Compares the errors.csv of evaluate output folders: per cell, the "
                    "median over runs and the worst run of each run's median error, "
                    "flagged beyond 10 %% + 0.5 mm; then the ratio of run medians, after "
                    "over before, with a 95 %% bootstrap interval. Each side may pool "
                    "several folders (the same sweep with other image.seed values).",
        epilog="examples:\n  drake-tracker compare out/quick out/quick_new\n"
               "  drake-tracker compare out/s100,out/s200 out/new_s100,out/new_s200")
    p.add_argument("before", help="evaluate output folder(s), comma-separated")
    p.add_argument("after", help="evaluate output folder(s), comma-separated")
    p.add_argument("--method", default="full_fusion", help="(default: %(default)s)")
    p.add_argument("--settle-s", type=float, default=5.0,
                   help="errors from this time on (s, default %(default)s)")

    def run(args):
        from drake_tracker.evaluation.compare import compare, format_comparison

        try:
            result = compare([Path(f) for f in args.before.split(",")],
                             [Path(f) for f in args.after.split(",")],
                             args.method, args.settle_s)
        except ValueError as err:
            raise UsageError(str(err)) from None
        print(format_comparison(result))
        return 0

    p.set_defaults(func=run)


def _add_servo(sub) -> None:
    p = sub.add_parser(
        "servo", help="closed-loop study: servo the hand to targets, with and without the "
                      "tracker",
        description="Simulates the robot (dynamic) servoing its hand to targets given in "
                    "the camera frame three times, the same controller fed by (a) the "
                    "encoders with the nominal camera, (b) drake_tracker's X_CE, (c) the "
                    "truth; prints each target's final true error and settle time and the "
                    "real-time factors, and writes report.json, servo_errors.png, "
                    "errors.csv and meshcat.html to --out.",
        epilog="examples:\n  drake-tracker servo --out out/servo\n"
               "  drake-tracker servo --scenario static/time-varying --out out/servo_tv\n"
               "  drake-tracker servo --print-config > servo.yaml")
    p.add_argument("--config", default=None, metavar="YAML",
                   help="study configuration (drake_tracker.servo.config.ServoStudyConfig; "
                        "--print-config prints the defaults)")
    p.add_argument("--scenario", default=None,
                   help="the world's scenario, over the config's (default static/constant; "
                        "static/time-varying: bias steps)")
    p.add_argument("--out", default="out/servo", help="output folder (default: %(default)s)")
    p.add_argument("--duration", type=positive_seconds, default=None, metavar="SECONDS",
                   help="stop each run this early (default: hold + every dwell)")
    p.add_argument("--runs", default=None,
                   help="comma-separated subset of encoders,tracker,truth (default: all)")
    p.add_argument("--params", default=None, metavar="YAML", help=PARAMS_HELP)
    p.add_argument("--no-meshcat", action="store_true", help="no Meshcat recording")
    p.add_argument("--print-config", action="store_true",
                   help="print the configuration as YAML and exit")

    def run(args):
        from drake_tracker.servo.config import FEEDBACKS, servo_config_to_yaml

        config = load_servo_config_arg(args.config, args.scenario)
        if args.print_config:
            print(servo_config_to_yaml(config), end="")
            return 0
        unknown = set((args.runs or "").split(",")) - set(FEEDBACKS) - {""}
        if unknown:
            raise UsageError(f"unknown runs {sorted(unknown)}; valid: {', '.join(FEEDBACKS)}")
        params = load_params_arg(args.params or config.tracker_params or None)
        check_out_dir(args.out)
        from drake_tracker.servo.report import run_servo_command

        return run_servo_command(args, config, params)

    p.set_defaults(func=run)


def build_parser() -> argparse.ArgumentParser:
    """The ``drake-tracker`` parser with every subcommand."""
    parser = argparse.ArgumentParser(
        prog="drake-tracker", description=DESCRIPTION,
        formatter_class=lambda prog: argparse.RawDescriptionHelpFormatter(
            prog, max_help_position=16))
    parser.add_argument("--version", action="version", version=_version())
    parser.add_argument("--debug", action="store_true", default=False,
                        help="show the full traceback of an error")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND",
                                parser_class=_CommandParser)
    for add in (_add_demo, add_record, add_track, add_calibrate, _add_bench, _add_evaluate,
                _add_compare, _add_scenarios, _add_params, _add_servo):
        add(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Runs one command; a mistake in the arguments prints one line and returns 2."""
    parser = build_parser()
    args, unknown = parser.parse_known_args(argv)
    command_parser = getattr(args, "_parser", parser)
    if unknown:
        command_parser.error(f"unrecognized arguments: {' '.join(unknown)}")
    try:
        if getattr(args, "params", None):
            load_params_arg(args.params)
        return int(args.func(args) or 0)
    except UsageError as err:
        if args.debug:
            raise
        print(f"{command_parser.prog}: error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        if args.debug:
            raise
        print(f"{command_parser.prog}: interrupted", file=sys.stderr)
        return 130
    except SystemExit as stop:
        # A command that stops with a message (``SystemExit("...")``) made the same kind
        # of one-line error: the same format and exit code 2.
        if isinstance(stop.code, str) and not args.debug:
            print(f"{command_parser.prog}: error: {stop.code}", file=sys.stderr)
            raise _MessageExit(stop.code) from None
        raise


if __name__ == "__main__":
    sys.exit(main())
