"""Replays one recorded run with variants of the tracker's parameters and prints the
hand-pose errors: the evidence behind the defaults in ``drake_tracker/params/tracker_params.py``
(see ``docs/defaults.md``).

    drake-tracker record --scenario s-full-arm/constant --out runs/default.npz
    python examples/parameter_study.py runs/default.npz --duration 6 \\
        --variant default \\
        --variant "kalman.robot_joints.bias_process_std_rad_per_sqrt_s=0.05" \\
        --variant "image.annealing_betas=[1.0];image.num_particles=150"

A variant is ``;``-separated ``dotted.field=value`` overrides of ``TrackerParams``
(values are parsed as YAML), or ``default``.
"""

import argparse
import dataclasses
import time

from pydrake.common.yaml import yaml_load

from drake_tracker.io.recording import RecordedRun
from drake_tracker.io.replay import encoders_only_X_CE, model_for_run, replay_run
from drake_tracker.metrics import percentile_summary, pose_errors
from drake_tracker.params.tracker_params import TrackerParams
from drake_tracker.params.validation import validate_tracker_params


def truncate(run: RecordedRun, duration_s: float) -> RecordedRun:
    """The first ``duration_s`` seconds of a run (images by arrival time)."""
    r = run.reading_times_s <= duration_s
    i = run.image_arrival_times_s <= duration_s
    t = run.truth_times_s <= duration_s
    return dataclasses.replace(
        run, reading_times_s=run.reading_times_s[r], readings_rad=run.readings_rad[r],
        image_capture_times_s=run.image_capture_times_s[i],
        image_arrival_times_s=run.image_arrival_times_s[i],
        depth_images_m=run.depth_images_m[i], truth_times_s=run.truth_times_s[t],
        truth_positions_rad=run.truth_positions_rad[t], truth_bias_rad=run.truth_bias_rad[t],
        truth_camera_offset=run.truth_camera_offset[t], truth_X_CE=run.truth_X_CE[t])


def apply_variant(params: TrackerParams, variant: str) -> TrackerParams:
    if variant == "default":
        return params
    for assignment in variant.split(";"):
        path, _, text = assignment.partition("=")
        *parents, leaf = path.strip().split(".")
        target = params
        for name in parents:
            target = getattr(target, name)
        if not hasattr(target, leaf):
            raise SystemExit(f"unknown parameter '{path}'")
        setattr(target, leaf, yaml_load(data=f"value: {text}")["value"])
    validate_tracker_params(params)
    return params


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run")
    parser.add_argument("--duration", type=float, default=None, help="replay only this long")
    parser.add_argument("--settle", type=float, default=0.0,
                        help="ignore errors before this time (s)")
    parser.add_argument("--variant", action="append", default=[])
    args = parser.parse_args()
    run = RecordedRun.load(args.run)
    if args.duration:
        run = truncate(run, args.duration)
    model = model_for_run(run)
    after = run.truth_times_s >= max(args.settle, 1e-9)

    def row(name, X, seconds):
        t_err, r_err = pose_errors(X[after], run.truth_X_CE[after])
        t, r = percentile_summary(t_err), percentile_summary(r_err)
        print(f"{name[:60]:<60} {t['p50']:8.1f} {t['p75']:8.1f} {r['p50']:7.2f} "
              f"{seconds:7.0f}", flush=True)

    print(f"{'variant':<60} {'p50 mm':>8} {'p75 mm':>8} {'p50 deg':>7} {'wall s':>7}")
    row("encoders_only", encoders_only_X_CE(run, model), 0.0)
    for variant in args.variant or ["default"]:
        params = apply_variant(TrackerParams(), variant)
        start = time.perf_counter()
        result = replay_run(run, params, model)
        row(variant, result.X_CE, time.perf_counter() - start)


if __name__ == "__main__":
    main()
