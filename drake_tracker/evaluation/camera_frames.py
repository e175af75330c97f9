"""Each camera's frame against the truth: what the evaluation writes beside errors.csv.

``errors.csv`` holds the output, the hand in the first camera's estimated frame (``X_CE``),
as the paper measures it. A tracker with several cameras is judged by more than that:
the hand in a camera that sees the arm is held to millimetres while the first camera's
frame, blind, is not (``docs/evaluation.md``, "Two cameras"). For every sample of a
replayed method and every camera of the model, against the model at the true joint
angles and camera offsets (for a world that differs from its model, the model's hand
there, not the world's):

* ``hand_mm``, ``hand_deg``: the hand in the camera's estimated frame against the hand in
  its true frame (``TrackerEstimate.X_CkE``); for the first camera, ``errors.csv``'s;
* ``pose_mm``, ``pose_deg``: the camera's estimated pose in the world against its true
  pose (``TrackerEstimate.X_WC_by_camera``);
* ``offset_mm``, ``offset_deg``: the norms of the differences of its six offset values,
  x, y, z and rx, ry, rz (the virtual joints' values, as the scenarios state a mounting
  error; not a distance between poses).

``cameras.csv`` has every sample; ``cameras.md``, per sequence, bias, method and camera,
the median over seeds of each seed's whole-run p50 / p75 of the hand (the worst seed's
p50), of the pose, and of the offset from the settling time on.
"""

from __future__ import annotations

import csv
import io
import math
from collections import defaultdict
from collections.abc import Iterable
from typing import TYPE_CHECKING

import numpy as np

from drake_tracker.evaluation.summary import is_settled
from drake_tracker.metrics import pose_errors

if TYPE_CHECKING:
    from drake_tracker.io.recording import RecordedRun
    from drake_tracker.robot.model import TrackerModel

#: The per-sample columns of ``cameras.csv``.
CAMERA_COLUMNS = ("sequence", "bias", "method", "seed", "time_s", "camera", "hand_mm",
                  "hand_deg", "pose_mm", "pose_deg", "offset_mm", "offset_deg")
_ERRORS = ("hand_mm", "hand_deg", "pose_mm", "pose_deg", "offset_mm", "offset_deg")


def true_positions(run: RecordedRun, model: TrackerModel, index: np.ndarray) -> np.ndarray:
    """(T, n) the model's positions at the run's truth samples ``index``: the true robot
    angles, and each camera's true offset on its six virtual joints. A run of one camera
    is the model's first camera's, as a replay takes it; several are matched by name.
    ValueError names a camera of the model the run has no truth for."""
    offsets = run.truth_offsets_by_camera
    if not run.other_cameras:
        offsets = {model.camera_names[0]: run.truth_camera_offset}
    missing = [name for name in model.camera_names if name not in offsets]
    if missing:
        raise ValueError(f"the run has no truth for the model's cameras {missing} (it has "
                         f"{list(offsets)})")
    q = np.zeros((len(index), model.num_joints))
    q[:, model.robot_joint_indices] = run.truth_positions_rad[index]
    for name in model.camera_names:
        q[:, model.camera_joint_indices(name)] = offsets[name][index]
    return q


def camera_frame_errors(model: TrackerModel, positions: np.ndarray, truth: np.ndarray,
                        truth_poses: dict | None = None) -> dict[str, dict[str, np.ndarray]]:
    """Per camera of ``model``, the (T,) errors of the module's list, estimated positions
    ``positions`` (T, n; NaN rows, before the tracker started, give NaN) against
    ``truth`` (T, n), through the model's plant. ``truth_poses``: :func:`camera_poses`
    of ``truth``, when the caller scores several estimates against one truth."""
    positions, truth = np.asarray(positions, float), np.asarray(truth, float)
    if positions.shape != truth.shape or positions.ndim != 2 or (
            positions.shape[1] != model.num_joints):
        raise ValueError(f"positions {positions.shape} and truth {truth.shape} must both "
                         f"be (T, {model.num_joints})")
    est = camera_poses(model, positions)
    true = camera_poses(model, truth) if truth_poses is None else truth_poses
    X_WE_est, X_WE_true = est[None], true[None]
    ok = np.all(np.isfinite(positions), axis=1)
    out = {}
    for name in model.camera_names:
        errors = {key: np.full(len(positions), np.nan) for key in _ERRORS}
        hand_est = np.linalg.inv(est[name][ok]) @ X_WE_est[ok]
        hand_true = np.linalg.inv(true[name][ok]) @ X_WE_true[ok]
        errors["hand_mm"][ok], errors["hand_deg"][ok] = pose_errors(hand_est, hand_true)
        errors["pose_mm"][ok], errors["pose_deg"][ok] = pose_errors(est[name][ok],
                                                                    true[name][ok])
        joints = model.camera_joint_indices(name)
        difference = positions[ok][:, joints] - truth[ok][:, joints]
        errors["offset_mm"][ok] = 1000.0 * np.linalg.norm(difference[:, :3], axis=1)
        errors["offset_deg"][ok] = np.degrees(np.linalg.norm(difference[:, 3:], axis=1))
        out[name] = errors
    return out


def camera_poses(model: TrackerModel, positions: np.ndarray) -> dict:
    """{camera name: (T, 4, 4) X_WC, None: (T, 4, 4) X_WE} at each row of ``positions``
    (identity where a row is not finite)."""
    plant = model.plant
    context = plant.CreateDefaultContext()
    world = plant.world_frame()
    frames = {name: model.camera(name).frame for name in model.camera_names}
    frames[None] = model.end_effector_frame
    poses = {key: np.tile(np.eye(4), (len(positions), 1, 1)) for key in frames}
    for t, q in enumerate(positions):
        if not np.all(np.isfinite(q)):
            continue
        plant.SetPositions(context, q)
        for key, frame in frames.items():
            poses[key][t] = plant.CalcRelativeTransform(context, world, frame).GetAsMatrix4()
    return poses


def camera_errors_csv_text(sequence: str, bias: str, seed: int, times_s: np.ndarray,
                           by_method: dict[str, dict[str, dict[str, np.ndarray]]]) -> str:
    """The CSV (columns :data:`CAMERA_COLUMNS`) of one task: ``by_method`` maps a method
    to :func:`camera_frame_errors`' result at ``times_s``."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(CAMERA_COLUMNS)
    for method, cameras in by_method.items():
        for camera, errors in cameras.items():
            for k, t in enumerate(times_s):
                writer.writerow([sequence, bias, method, seed, f"{t:.4f}", camera,
                                 *(f"{errors[key][k]:.4f}" for key in _ERRORS)])
    return buffer.getvalue()


def camera_summary(rows: Iterable[dict], settle_s: float) -> str:
    """Markdown: per sequence, bias, method and camera (``cameras.csv``'s rows), the
    median over seeds of each seed's whole-run p50 / p75 of the hand in that camera's
    frame (worst seed's p50), of its pose in the world, and of its offset from
    ``settle_s`` on (worst seed)."""
    runs: dict[tuple, dict[str, list]] = defaultdict(lambda: defaultdict(list))
    for row in rows:
        key = (row["sequence"], row["bias"], row["method"], row["camera"], row["seed"])
        late = is_settled(row, settle_s)
        for name in _ERRORS:
            value = float(row[name])
            if math.isfinite(value):
                runs[key][name].append(value)
                if late:
                    runs[key][name + "_settled"].append(value)
    cells: dict[tuple, list] = defaultdict(list)
    for key, values in runs.items():
        cells[key[:4]].append(values)
    lines = ["| sequence | bias | method | camera | seeds | hand in its frame: p50 / p75 "
             "mm (worst p50) | hand: p50 deg | its pose in the world: p50 mm, deg | its "
             f"offset from {settle_s:g} s: mm (worst), deg (worst) |",
             "|---|---|---|---|---|---|---|---|---|"]
    unsettled = False
    for (sequence, bias, method, camera), seeds in sorted(cells.items()):
        hand = _per_seed(seeds, "hand_mm")
        offset_mm = _per_seed(seeds, "offset_mm_settled")
        offset_deg = _per_seed(seeds, "offset_deg_settled")
        unsettled |= not np.isfinite(offset_mm).any()
        lines.append(
            f"| {sequence} | {bias} | {method} | {camera} | {len(seeds)} | "
            f"{_text(_median(hand), 1)} / {_text(_median(_per_seed(seeds, 'hand_mm', 75)), 1)} "
            f"({_text(_worst(hand), 1)}) | {_text(_median(_per_seed(seeds, 'hand_deg')), 2)} | "
            f"{_text(_median(_per_seed(seeds, 'pose_mm')), 1)}, "
            f"{_text(_median(_per_seed(seeds, 'pose_deg')), 2)} | "
            f"{_text(_median(offset_mm), 1)} ({_text(_worst(offset_mm), 1)}), "
            f"{_text(_median(offset_deg), 2)} ({_text(_worst(offset_deg), 2)}) |")
    if unsettled:
        lines += ["", f"n/a: no sample from {settle_s:g} s on (a run shorter than the "
                      f"settling time, `--settle-s`)."]
    return "\n".join(lines)


def _text(value: float, digits: int) -> str:
    """``value`` with ``digits`` decimals, or ``n/a`` for no value (NaN)."""
    return f"{value:.{digits}f}" if math.isfinite(value) else "n/a"


def _per_seed(seeds: list[dict], name: str, percentile: float = 50.0) -> np.ndarray:
    """Each seed's ``percentile`` of its samples of ``name`` (NaN: none)."""
    return np.array([np.percentile(s[name], percentile) if s[name] else np.nan
                     for s in seeds])


def _median(values: np.ndarray) -> float:
    finite = values[np.isfinite(values)]
    return float(np.median(finite)) if len(finite) else math.nan


def _worst(values: np.ndarray) -> float:
    finite = values[np.isfinite(values)]
    return float(np.max(finite)) if len(finite) else math.nan
