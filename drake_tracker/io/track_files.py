"""``drake-tracker track``: a recorded run, a bag or an LCM log in, estimates and a
report out.

All inputs go through one path, :func:`track_to_folder`: events (``io/stream.py``) into
the offline tracker, each estimate into ``estimates.csv`` and ``estimates.mcap``
(``io/estimates_out.py``), and ``report.json`` with the counts of what was used and
skipped (and why), and error percentiles when the input carries a truth.
"""

from __future__ import annotations

import json
import logging
import time
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from drake_tracker.io.estimates_out import EstimatesCsv, EstimateSinks
from drake_tracker.io.stream import Event, ImageEvent, ReadingEvent, merge_by_time, track_stream
from drake_tracker.metrics import format_report_table, method_report
from drake_tracker.tracker import Tracker

if TYPE_CHECKING:
    from drake_tracker.core.calibration.online import HeldCameras
    from drake_tracker.core.filter.estimate import TrackerEstimate
    from drake_tracker.core.sensors.camera import CameraIntrinsics
    from drake_tracker.io.bag_source import BagSource
    from drake_tracker.io.lcm_log import LcmLogSource
    from drake_tracker.io.recording import RecordedRun
    from drake_tracker.params.tracker_params import TrackerParams
    from drake_tracker.robot.model import TrackerModel

log = logging.getLogger(__name__)


def run_events(run: RecordedRun) -> Iterator[Event]:
    """A recorded run's events in arrival order: each reading at its stamp, each image at
    its recorded arrival (after the readings stamped at it; at one time, the cameras in
    the run's order). Images without an arrival time are skipped and counted
    (``CameraImages.arrival_order``)."""
    from drake_tracker.io.stream import SkippedMessage

    several = bool(run.other_cameras)
    streams = []
    for camera in run.cameras:
        order, unplayable = camera.arrival_order()
        of = f" of camera '{camera.name}'" if several else ""
        for i in unplayable:
            yield SkippedMessage("images without an arrival time", f"image {i}{of} "
                                 f"skipped: its arrival stamp is "
                                 f"{float(camera.arrival_times_s[i])!r}, not a time")
        streams.append(_camera_images(camera, order, camera.name if several else None))
    readings = ((float(t), ReadingEvent(float(t), q))
                for t, q in zip(run.reading_times_s, run.readings_rad))
    yield from merge_by_time(readings, *streams)


def _camera_images(camera, order: np.ndarray,
                   name: str | None) -> Iterator[tuple[float, ImageEvent]]:
    """(arrival, image) of a camera's images (``io/recording.CameraImages``) in
    ``order``, each named ``name`` (None: a run's one camera)."""
    for i in order:
        arrival = float(camera.arrival_times_s[i])
        yield arrival, ImageEvent(float(camera.capture_times_s[i]), camera.depth_images_m[i],
                                  int(i), arrival, name)


class TruthSampler:
    """Keeps the estimate's X_CE at each truth time (the latest estimate at or before
    it), streaming: the estimates are never all held."""

    def __init__(self, times_s: np.ndarray) -> None:
        self.times_s = np.asarray(times_s, float)
        self.X_CE = np.full((len(self.times_s), 4, 4), np.nan)
        self._next = 0
        self._latest: np.ndarray | None = None

    def write(self, estimate: TrackerEstimate) -> None:
        """Fills the truth times before ``estimate`` with the previous estimate."""
        while self._next < len(self.times_s) and self.times_s[self._next] < estimate.time_s:
            if self._latest is not None:
                self.X_CE[self._next] = self._latest
            self._next += 1
        self._latest = np.array(estimate.X_CE)

    def close(self) -> None:
        """The truth times after the last estimate get it."""
        if self._latest is not None:
            self.X_CE[self._next:] = self._latest
        self._next = len(self.times_s)


@dataclass(frozen=True)
class Truth:
    """The input's true hand poses: (T,) times (s, stream time) and (T, 4, 4) X_CE."""

    times_s: np.ndarray
    X_CE: np.ndarray


def track_to_folder(events: Iterable[Event], model: TrackerModel,
                    camera: CameraIntrinsics | dict[str, CameraIntrinsics],
                    params: TrackerParams | None,
                    out_dir: str | Path | None, base_ns: int = 0,
                    camera_frames: Mapping[str, str] | None = None,
                    truth: Truth | None = None,
                    total_images: int | None = None, source: dict | None = None,
                    progress: bool = True) -> dict:
    """Tracks ``events`` and writes ``estimates.csv``, ``estimates.mcap`` (when the
    ``ros`` extra is installed) and ``report.json`` into ``out_dir`` (None: nothing is
    written); returns the report. ``camera``: the one camera's intrinsics, or several
    cameras' by name (``Tracker(cameras=...)``; the events name their camera).
    ``camera_frames``: the input's frame id of each camera by name, the cameras' parents
    on ``estimates.mcap``'s ``/tf`` (``EstimatesBag``; None, or a camera left out: the
    model's frame name)."""
    tracker = (Tracker(model, params=params, cameras=camera) if isinstance(camera, dict)
               else Tracker(model, camera, params))
    sinks = []
    out = Path(out_dir) if out_dir is not None else None
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
        sinks.append(EstimatesCsv(out / "estimates.csv", model, base_ns))
        bag = _estimates_bag(out / "estimates.mcap", model, base_ns, camera_frames)
        sinks.append(bag)
    sampler = TruthSampler(truth.times_s) if truth is not None else None
    sink = EstimateSinks(*sinks, sampler)
    start = time.perf_counter()
    try:
        counts = track_stream(events, tracker, sink, total_images, progress)
    finally:
        sink.close()
    report = {"input": source or {}, "counts": counts.as_dict(),
              "wall_time_s": time.perf_counter() - start,
              "files": [s.path.name for s in sinks if s is not None]}
    if tracker.calibration is not None:
        report["camera_calibration"] = calibration_report(tracker.held, model)
    if sampler is not None:
        ok = np.all(np.isfinite(sampler.X_CE.reshape(len(sampler.X_CE), -1)), axis=1)
        report["methods"] = {"full_fusion": method_report(sampler.X_CE[ok], truth.X_CE[ok])}
    if out is not None:
        (out / "report.json").write_text(json.dumps(report, indent=2))
    return report


def calibration_report(held: HeldCameras | None, model: TrackerModel) -> dict:
    """What the cameras' calibration while tracking found (``core/calibration/online.py``):
    the window, the log-likelihood before and after the fit, its cost, each camera's
    offsets (``camera_offsets``: x, y, z in m, rx, ry, rz in rad) and the joints held at
    their readings; ``{"calibrated": false}`` when no window came."""
    if held is None:
        return {"calibrated": False}
    return {"calibrated": True, "window_s": list(held.window_s),
            "log_likelihood": list(held.log_likelihood), "evaluations": held.evaluations,
            "fit_wall_s": held.fit_wall_s,
            "camera_offsets": {name: held.offsets[model.camera_joint_indices(name)].tolist()
                               for name in model.camera_names},
            "trusted_joints": [model.joint_names[j] for j in np.flatnonzero(held.trusted)]}


def _estimates_bag(path: Path, model: TrackerModel, base_ns: int,
                   camera_frames: Mapping[str, str] | None):
    try:
        from drake_tracker.io.estimates_out import EstimatesBag

        if path.exists():
            path.unlink()
        return EstimatesBag(path, model, base_ns, camera_frames)
    except ImportError as err:
        log.warning("estimates.mcap not written: %s", err)
        return None


def print_report(report: dict) -> None:
    """The report in a few lines: counts, and error percentiles when there is a truth."""
    c = report["counts"]
    print(f"{c['readings']} readings, {c['images']} images: {c['images_applied']} applied; "
          f"{c['estimates']} estimates written")
    for name, mine in c.get("cameras", {}).items():
        print(f"  camera {name}: {mine['images']} images, {mine['applied']} applied, "
              f"{mine['skipped']} skipped")
    for name in ("source_skipped", "readings_skipped", "images_skipped"):
        if c[name]:
            print(f"  {name.replace('_', ' ')}: " +
                  ", ".join(f"{v} {k}" for k, v in sorted(c[name].items())))
    calibration = report.get("camera_calibration")
    if calibration is not None and calibration["calibrated"]:
        start, end = calibration["window_s"]
        print(f"  the cameras calibrated themselves on their images of {start:.2f}-{end:.2f} s "
              f"({calibration['fit_wall_s']:.1f} s) and are held there: camera_offsets " +
              json.dumps({k: [round(v, 5) for v in o]
                          for k, o in calibration["camera_offsets"].items()}))
    elif calibration is not None:
        print("  the cameras did not calibrate themselves: no window in which every "
              "camera tracked and saw the arm (camera_calibration.window_s)")
    if "methods" in report:
        print(format_report_table(report))


def track_bag(source: BagSource, model: TrackerModel, params: TrackerParams | None,
              out_dir: str | Path | None, progress: bool = True) -> dict:
    """Tracks an open ``io/bag_source.BagSource`` into ``out_dir`` (see
    :func:`track_to_folder`); the bag's truth topic, if any, gives error percentiles,
    and each camera's frame id in the bag is its parent on ``estimates.mcap``'s
    ``/tf``."""
    truth = source.truth_X_CE()
    warn_unfed_cameras(model, [c.name for c in source.cameras], "--depth-topic NAME=TOPIC")
    try:
        return track_to_folder(
            source.events(), model, source.camera_models(), params, out_dir, source.base_ns,
            source.frame_ids(model.camera_names[0]),
            Truth(*truth) if truth is not None else None,
            source.num_images, {"bag": str(source.path), "joint_topic": source.joint_topic,
                                "depth_topic": source.depth_topic,
                                "camera_info_topic": source.camera_info_topic,
                                **({"cameras": {c.name: [c.depth_topic, c.camera_info_topic]
                                                for c in source.cameras}}
                                   if len(source.cameras) > 1 else {})},
            progress)
    finally:
        source.close()


def track_run(run: RecordedRun, model: TrackerModel, params: TrackerParams | None,
              out_dir: str | Path | None, progress: bool = True) -> dict:
    """Tracks a recorded run into ``out_dir`` (see :func:`track_to_folder`), against its
    truth; a run of several cameras with all of them."""
    cameras = run.intrinsics_by_camera if run.other_cameras else run.camera_intrinsics
    return track_to_folder(run_events(run), model, cameras, params, out_dir,
                           truth=Truth(run.truth_times_s, run.truth_X_CE),
                           total_images=len(run.image_capture_times_s) + sum(
                               len(c.capture_times_s) for c in run.other_cameras),
                           source={"run": "recorded run"}, progress=progress)


def track_lcm_log(source: LcmLogSource, model: TrackerModel, params: TrackerParams | None,
                  out_dir: str | Path | None, progress: bool = True) -> dict:
    """Tracks an ``io/lcm_log.LcmLogSource`` into ``out_dir`` (see
    :func:`track_to_folder`); an LCM log has no truth, so no error percentiles."""
    warn_unfed_cameras(model, [c.name for c in source.cameras], "--camera NAME=WxH:...")
    channels = ({"image_channels": {c.name: c.channel for c in source.cameras}}
                if source.cameras[0].name is not None else
                {"image_channel": source.image_channel})
    return track_to_folder(
        source.events(), model, source.camera_models(), params, out_dir, source.base_ns,
        total_images=source.num_images,
        source={"lcm_log": str(source.path), "status_channel": source.status_channel,
                "status_type": f"lcmt_{source.status_type}_status", **channels},
        progress=progress)


def warn_unfed_cameras(model: TrackerModel, fed: list[str | None], flag: str) -> None:
    """Warns of the model's cameras that no input camera feeds (``fed``: the input's
    camera names, None: the model's first camera)."""
    named = {name or model.camera_names[0] for name in fed}
    unfed = [name for name in model.camera_names if name not in named]
    if unfed:
        log.warning("the robot's camera(s) %s have no %s: they get no image, and the hand "
                    "in their frame rests on the other cameras and the encoders", unfed, flag)
