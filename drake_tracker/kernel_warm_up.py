"""The tracker's numba kernels, loaded (or, on a machine's first run, compiled) before a
simulation, so that its first simulated seconds do not pay for them.

numba compiles a kernel at its first call and keeps the machine code in its on-disk
cache (``__pycache__`` beside the sources), so later processes load it in moments; the
first run after an install compiles them all, about a minute on a 2-core machine.
Inside a Diagram that happens on the image update's worker during the first images,
while the Simulator waits for them at their deadlines: the README's demo command in a
fresh clone reported a real-time factor of 0.28 (73.5 s of waiting), against 0.75 at
its second run.
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING

from drake_tracker.io.replay import replay_run
from drake_tracker.io.synthetic import synthetic_run

if TYPE_CHECKING:
    from drake_tracker.core.sensors.camera import CameraIntrinsics
    from drake_tracker.params.tracker_params import TrackerParams
    from drake_tracker.robot.model import TrackerModel

#: Length of the synthetic recording replayed (s): its images include the start-up
#: search's and the tracking ones.
WARM_UP_RUN_S = 0.5


def warm_up_tracker_kernels(model: TrackerModel, camera: CameraIntrinsics,
                            params: TrackerParams) -> float:
    """Replays a short synthetic recording (``model`` rendered at the size of ``camera``
    by the batched renderer, ``synthetic.synthetic_run``) through the offline
    :class:`~drake_tracker.tracker.Tracker` with ``params``, so that every kernel the
    joint filter and the image update call is compiled and loaded in this process.
    Returns the seconds it took."""
    start = time.perf_counter()
    run = synthetic_run(model, duration_s=WARM_UP_RUN_S, camera=camera, seed=0)
    result = replay_run(run, params, model=model)
    if result.num_images_applied == 0:
        raise RuntimeError("warm_up_tracker_kernels: no synthetic image was applied, so "
                           "the image update's kernels were not loaded")
    return time.perf_counter() - start


#: Whether :func:`warm_up_once` has loaded the kernels in this process.
_loaded_in_process = False


def warm_up_once(model: TrackerModel, camera: CameraIntrinsics,
                 params: TrackerParams) -> float | None:
    """:func:`warm_up_tracker_kernels` at this process's first call, its seconds; None at
    the later ones (the kernels are loaded). For processes that track many runs and time
    each (the evaluation's workers): a worker's first task took 27 s of image updates and
    12 s of decision against 3.9 and 0.12 s for the next ones (a fresh worktree's first
    quick suite, Zen 5 VM), and the decision's share of the quick suite read 11.6 %
    instead of 8.9 %."""
    global _loaded_in_process
    if _loaded_in_process:
        return None
    seconds = warm_up_tracker_kernels(model, camera, params)
    _loaded_in_process = True
    return seconds
