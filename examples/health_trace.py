"""Replays one protocol task's recorded run through the offline ``Tracker`` as the
protocol's full-fusion method does, and prints, for the images in a time window, the
hand error against the truth, the health state with the latest image's consistency,
whether a challenger is searching, the camera offset, and the arm's biases and angles.

It is how the protocol's lost seeds are read: for example the run in which a bias step
at 50 s left joint 4's bias estimate at 119 degrees for 10 s while the health said
``TRACKING`` (``docs/evaluation_full/RUN.md``)::

    python examples/health_trace.py docs/evaluation_full/runs/arm__time-varying__seed8.npz \
        --seed 8 --from-s 49.3 --to-s 60

The run files are written by ``drake-tracker evaluate`` into ``--out``/runs.
"""

from __future__ import annotations

import argparse

import numpy as np

from drake_tracker.core.frames import DepthFrame
from drake_tracker.methods import method_params
from drake_tracker.offline import model_for_run
from drake_tracker.recording import RecordedRun
from drake_tracker.tracker import Tracker


def trace(run: RecordedRun, seed: int, from_s: float, to_s: float, every_s: float,
          min_image_interval_s: float) -> None:
    """Prints one line per image captured in [from_s, to_s], at most one per every_s."""
    model = model_for_run(run)
    initial = {n: float(q) for n, q in zip(run.joint_names, run.truth_positions_rad[0])}
    params = method_params("full_fusion", None, initial_positions_rad=initial)
    params.image.min_image_interval_s = min_image_interval_s
    params.image.seed += seed
    tracker = Tracker(model, run.camera_intrinsics, params)
    order = np.argsort(run.image_arrival_times_s, kind="stable")
    virtual = model.virtual_joint_indices
    arm = [i for i in range(model.num_joints) if i not in set(virtual)]
    next_image, last_printed = 0, -np.inf
    for k, t in enumerate(run.reading_times_s):
        while next_image < len(order) and run.image_arrival_times_s[order[next_image]] < t:
            i = order[next_image]
            next_image += 1
            captured = float(run.image_capture_times_s[i])
            tracker.add_image(DepthFrame(captured, float(run.image_arrival_times_s[i]),
                                         run.depth_images_m[i], int(i)))
            if captured > to_s:
                return
            if captured < from_s or captured - last_printed < every_s:
                continue
            last_printed = captured
            health, estimate = tracker.health, tracker.estimate()
            latest = health.latest
            truth = min(np.searchsorted(run.truth_times_s, captured), len(run.truth_times_s) - 1)
            error_mm = 1000 * np.linalg.norm(estimate.X_CE[:3, 3] - run.truth_X_CE[truth][:3, 3])
            consistency = (f"pixels {latest.robot_pixels} agree {latest.agreement:.2f} "
                           f"see-through {latest.see_through:.2f} occluded {latest.occluded:.2f}"
                           if latest else "no image yet")
            print(f"{captured:7.2f} s  error {error_mm:6.0f} mm  {health.state.name}  "
                  f"{consistency}  challenger {health.challenger is not None}  "
                  f"camera {np.round(estimate.positions[virtual], 3)}  "
                  f"bias deg {np.round(np.degrees(estimate.biases[arm]), 1)}  "
                  f"angle deg {np.round(np.degrees(estimate.positions[arm]), 1)}", flush=True)
        tracker.add_reading(float(t), run.readings_rad[k])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("run", help="a recorded run (.npz), e.g. from evaluate's runs/")
    parser.add_argument("--seed", type=int, default=0, help="the task's seed")
    parser.add_argument("--from-s", type=float, default=0.0)
    parser.add_argument("--to-s", type=float, default=np.inf)
    parser.add_argument("--every-s", type=float, default=0.45)
    parser.add_argument("--min-image-interval-s", type=float, default=0.1,
                        help="the protocol's image pacing (evaluate's tasks use 0.1)")
    args = parser.parse_args()
    import numba

    numba.set_num_threads(1)
    trace(RecordedRun.load(args.run), args.seed, args.from_s, args.to_s, args.every_s,
          args.min_image_interval_s)


if __name__ == "__main__":
    main()
