"""The ``drake-tracker`` command line: demo, record, track, bench, evaluate.

Each subcommand's work lives in its own module; this file only parses arguments.
"""

from __future__ import annotations

import argparse
import sys


def _add_demo(sub) -> None:
    p = sub.add_parser("demo", help="simulate a scenario, track it, and write a report")
    p.add_argument("--scenario", default="s-full-arm/constant",
                   help="preset name or YAML file (default: %(default)s)")
    p.add_argument("--out", default="out/demo", help="output folder (default: %(default)s)")
    p.add_argument("--duration", type=float, default=None,
                   help="override the scenario duration (s)")
    p.add_argument("--params", default=None, help="tracker parameters YAML file")

    def run(args):
        from drake_tracker.demo import run_demo

        return run_demo(args)

    p.set_defaults(func=run)


def _add_record(sub) -> None:
    p = sub.add_parser("record", help="simulate a scenario and write a recorded run (.npz)")
    p.add_argument("--scenario", default="s-full-arm/constant")
    p.add_argument("--out", required=True, help="output .npz file")
    p.add_argument("--duration", type=float, default=None,
                   help="override the scenario duration (s)")
    p.add_argument("--image-stride", type=int, default=8,
                   help="store every N-th pixel of each image (default: %(default)s)")

    def run(args):
        from drake_tracker.sim.record import run_record

        return run_record(args)

    p.set_defaults(func=run)


def _add_track(sub) -> None:
    p = sub.add_parser("track", help="replay a recorded run through the offline tracker")
    p.add_argument("--run", required=True, help="recorded run (.npz)")
    p.add_argument("--params", default=None, help="tracker parameters YAML file")
    p.add_argument("--out", default=None, help="folder for report.json (optional)")

    def run(args):
        from drake_tracker.offline import run_track

        return run_track(args)

    p.set_defaults(func=run)


def _add_bench(sub) -> None:
    p = sub.add_parser("bench", help="benchmark the tracker's hot paths")
    p.add_argument("--out", default="out/bench", help="folder for bench.json")
    p.add_argument("--quick", action="store_true", help="fewer repetitions")

    def run(args):
        from drake_tracker.bench import run_bench

        return run_bench(args)

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


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="drake-tracker", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)
    for add in (_add_demo, _add_record, _add_track, _add_bench, _add_evaluate):
        add(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    result = args.func(args)
    return int(result or 0)


if __name__ == "__main__":
    sys.exit(main())
