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

from drake_tracker.core.sensors.depth_frames import DepthFrame
from drake_tracker.evaluation.tasks import QUICK_IMAGE_INTERVAL_S, protocol_params
from drake_tracker.io.recording import RecordedRun
from drake_tracker.io.replay import model_for_run, replay_run
from drake_tracker.tracker import Tracker


class _PastTheWindowError(Exception):
    """Raised by the per-image callback once an image was captured after the window."""


def trace_lines(run: RecordedRun, seed: int, from_s: float, to_s: float, every_s: float,
                min_image_interval_s: float) -> list[str]:
    """One line per image captured in [from_s, to_s], at most one per ``every_s``, as the
    protocol's full-fusion replay of ``run`` (task seed ``seed``) saw it; printed as
    they come. The first line names the joints whose biases and angles follow."""
    model = model_for_run(run)
    virtual = list(model.virtual_joint_indices)
    real = [i for i in range(model.num_joints) if i not in set(virtual)]
    names = [model.joint_names[i] for i in real]
    lines = [f"biases and angles (deg) of {', '.join(names)}; camera offset: the "
             f"{len(virtual)} virtual joints"]
    print(lines[0], flush=True)
    last_printed = -np.inf

    def on_image(tracker: Tracker, frame: DepthFrame) -> None:
        nonlocal last_printed
        captured = frame.capture_time_s
        if captured > to_s:
            raise _PastTheWindowError
        if captured < from_s or captured - last_printed < every_s:
            return
        last_printed = captured
        health, estimate = tracker.health, tracker.estimate()
        latest = health.latest
        truth = min(np.searchsorted(run.truth_times_s, captured), len(run.truth_times_s) - 1)
        error_mm = 1000 * np.linalg.norm(estimate.X_CE[:3, 3] - run.truth_X_CE[truth][:3, 3])
        consistency = (f"pixels {latest.robot_pixels} agree {latest.agreement:.2f} "
                       f"see-through {latest.see_through:.2f} occluded {latest.occluded:.2f}"
                       if latest else "no image yet")
        line = (f"{captured:7.2f} s  error {error_mm:6.0f} mm  {health.state.name}  "
                f"{consistency}  challenger {health.challenger is not None}  "
                f"camera {np.round(estimate.positions[virtual], 3)}  "
                f"bias {np.round(np.degrees(estimate.biases[real]), 1)}  "
                f"angle {np.round(np.degrees(estimate.positions[real]), 1)}")
        lines.append(line)
        print(line, flush=True)

    params = protocol_params(run, "full_fusion", min_image_interval_s, tracker_seed=seed)
    try:
        replay_run(run, params, model, on_image=on_image)
    except _PastTheWindowError:
        pass
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("run", help="a recorded run (.npz), e.g. from evaluate's runs/")
    parser.add_argument("--seed", type=int, default=0, help="the task's seed")
    parser.add_argument("--from-s", type=float, default=0.0)
    parser.add_argument("--to-s", type=float, default=np.inf)
    parser.add_argument("--every-s", type=float, default=0.45)
    parser.add_argument("--min-image-interval-s", type=float, default=QUICK_IMAGE_INTERVAL_S,
                        help="the protocol's image pacing (evaluate's tasks use "
                             f"{QUICK_IMAGE_INTERVAL_S})")
    args = parser.parse_args()
    import numba

    numba.set_num_threads(1)
    trace_lines(RecordedRun.load(args.run), args.seed, args.from_s, args.to_s, args.every_s,
          args.min_image_interval_s)


if __name__ == "__main__":
    main()
