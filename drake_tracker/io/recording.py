"""The recorded-run format: everything the offline tracker replays, plus ground truth.

A run is one compressed NumPy archive (``.npz``) with these arrays (n measured joints,
R readings, I images of H x W pixels, T ground-truth samples):

========================== =============== ==============================================
key                        shape / dtype    meaning
========================== =============== ==============================================
``format_version``         () int           2 (1: one camera, without ``camera_names``)
``robot_config_yaml``      () str           the RobotConfig, as YAML
``scenario_yaml``          () str           the scenario that produced it, as YAML ('' if none)
``joint_names``            (n,) str         the measured joints, in reading order
``reading_times_s``        (R,) float64     encoder sample times, strictly increasing
``readings_rad``           (R, n) float64   encoder readings (rad, or m for prismatic)
``image_capture_times_s``  (I,) float64     when each depth image was taken
``image_arrival_times_s``  (I,) float64     when it reached the tracker (>= capture time)
``depth_images_m``         (I, H, W) f32    depth along the optical axis (m); NaN = invalid
``camera_intrinsics``      (6,) float64     width, height, fx, fy, cx, cy of the stored images
``truth_times_s``          (T,) float64     ground-truth sample times
``truth_positions_rad``    (T, n) float64   true joint angles
``truth_bias_rad``         (T, n) float64   true encoder bias (reading minus angle, noise-free)
``truth_camera_offset``    (T, 6) float64   true camera offset [x y z (m), rx ry rz (rad)]
``truth_X_CE``             (T, 4, 4)        true hand pose in the true camera frame
========================== =============== ==============================================

The images, intrinsics and ``truth_camera_offset`` above are the first camera's (the
camera of ``truth_X_CE``). Version 2 adds ``camera_names`` (C,) str, every camera's name,
and for each further camera j = 1..C-1 ``camera{j}_image_capture_times_s``,
``camera{j}_image_arrival_times_s``, ``camera{j}_depth_images_m``,
``camera{j}_intrinsics`` and ``camera{j}_truth_camera_offset``, as the first camera's.
A version 1 file reads as a run of one camera named ``camera``.

Images are stored already subsampled (see ``image_stride`` of ``drake-tracker record``);
the intrinsics are those of the stored images.
"""

from __future__ import annotations

import dataclasses
import logging
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from drake_tracker.core.sensors.camera import CameraIntrinsics

log = logging.getLogger(__name__)

FORMAT_VERSION = 2
#: The versions :meth:`RecordedRun.load` reads.
READABLE_VERSIONS = (1, 2)
#: The name of the one camera of a version 1 run.
FIRST_CAMERA_NAME = "camera"
#: What each further camera stores (``camera{j}_<key>``), and the field it fills.
_CAMERA_KEYS = {"image_capture_times_s": "capture_times_s",
                "image_arrival_times_s": "arrival_times_s",
                "depth_images_m": "depth_images_m",
                "truth_camera_offset": "truth_camera_offset"}


@dataclass
class CameraImages:
    """The images of one further camera of a run (the first camera's are the run's own
    ``image_*``/``depth_images_m`` fields), with its intrinsics and true offset (T, 6)."""

    name: str
    intrinsics: CameraIntrinsics
    capture_times_s: np.ndarray
    arrival_times_s: np.ndarray
    depth_images_m: np.ndarray
    truth_camera_offset: np.ndarray

    def arrival_order(self) -> tuple[np.ndarray, np.ndarray]:
        """(indices of the images whose arrival stamp is a finite time, in arrival order;
        indices of those whose stamp is not: they cannot be played or written in arrival
        order, and a player skips, warns about and counts them)."""
        arrivals = np.asarray(self.arrival_times_s, float)
        order = np.argsort(arrivals, kind="stable")
        playable = np.isfinite(arrivals[order])
        return order[playable], order[~playable]

    def validate(self, num_truth: int) -> None:
        """Raises ValueError naming the camera and its first inconsistent field."""
        count = len(self.capture_times_s)
        cam = self.intrinsics
        if len(self.arrival_times_s) != count:
            raise ValueError(f"camera '{self.name}': arrival and capture times differ in "
                             "length")
        if np.any(self.arrival_times_s < self.capture_times_s):
            raise ValueError(f"camera '{self.name}': an image arrives before it was captured")
        if self.depth_images_m.shape != (count, cam.height, cam.width):
            raise ValueError(f"camera '{self.name}': depth_images_m has shape "
                             f"{self.depth_images_m.shape}, expected "
                             f"{(count, cam.height, cam.width)} from its intrinsics")
        if self.truth_camera_offset.shape != (num_truth, 6):
            raise ValueError(f"camera '{self.name}': truth_camera_offset has shape "
                             f"{self.truth_camera_offset.shape}, expected {(num_truth, 6)}")


@dataclass
class RecordedRun:
    """A recorded run in memory; see the module docstring for the fields."""

    robot_config_yaml: str
    joint_names: list[str]
    reading_times_s: np.ndarray
    readings_rad: np.ndarray
    image_capture_times_s: np.ndarray
    image_arrival_times_s: np.ndarray
    depth_images_m: np.ndarray
    camera_intrinsics: CameraIntrinsics
    truth_times_s: np.ndarray
    truth_positions_rad: np.ndarray
    truth_bias_rad: np.ndarray
    truth_camera_offset: np.ndarray
    truth_X_CE: np.ndarray
    scenario_yaml: str = ""
    extra: dict = field(default_factory=dict)
    #: The first camera's name (the images above are its images).
    camera_name: str = FIRST_CAMERA_NAME
    #: The further cameras' images, in the model's camera order.
    other_cameras: list[CameraImages] = field(default_factory=list)

    @property
    def camera_names(self) -> list[str]:
        """Every camera's name, the first first."""
        return [self.camera_name] + [c.name for c in self.other_cameras]

    @property
    def cameras(self) -> list[CameraImages]:
        """Every camera's images, the first first (the run's own image fields, as a
        :class:`CameraImages` that shares their arrays)."""
        first = CameraImages(self.camera_name, self.camera_intrinsics,
                             self.image_capture_times_s, self.image_arrival_times_s,
                             self.depth_images_m, self.truth_camera_offset)
        return [first, *self.other_cameras]

    @property
    def intrinsics_by_camera(self) -> dict[str, CameraIntrinsics]:
        """Every camera's intrinsics by name, the first first (``Tracker(cameras=...)``)."""
        return {c.name: c.intrinsics for c in self.cameras}

    @property
    def truth_offsets_by_camera(self) -> dict[str, np.ndarray]:
        """Every camera's (T, 6) true offset values by name, the first first."""
        return {c.name: c.truth_camera_offset for c in self.cameras}

    def __post_init__(self) -> None:
        self.validate()

    def validate(self) -> None:
        """Raises ValueError naming the first inconsistent field."""
        n = len(self.joint_names)
        R = len(self.reading_times_s)
        if self.readings_rad.shape != (R, n):
            raise ValueError(f"readings_rad has shape {self.readings_rad.shape}, expected {(R, n)}")
        if R > 1 and not np.all(np.diff(self.reading_times_s) > 0):  # NaN fails too
            k = int(np.flatnonzero(~(np.diff(self.reading_times_s) > 0))[0]) + 1
            raise ValueError(
                f"reading_times_s must be strictly increasing and finite: reading {k} is "
                f"stamped {float(self.reading_times_s[k])!r} s after "
                f"{float(self.reading_times_s[k - 1])!r} s "
                f"(a recorded log is replayed in stamp order; the live Tracker skips such "
                f"a reading with a warning)")
        num_images = len(self.image_capture_times_s)
        if len(self.image_arrival_times_s) != num_images:
            raise ValueError("image_arrival_times_s and image_capture_times_s differ in length")
        if np.any(self.image_arrival_times_s < self.image_capture_times_s):
            raise ValueError("an image arrives before it was captured")
        cam = self.camera_intrinsics
        if self.depth_images_m.shape != (num_images, cam.height, cam.width):
            raise ValueError(
                f"depth_images_m has shape {self.depth_images_m.shape}, expected "
                f"{(num_images, cam.height, cam.width)} from the intrinsics"
            )
        T = len(self.truth_times_s)
        for name, shape in (
            ("truth_positions_rad", (T, n)),
            ("truth_bias_rad", (T, n)),
            ("truth_camera_offset", (T, 6)),
            ("truth_X_CE", (T, 4, 4)),
        ):
            if getattr(self, name).shape != shape:
                raise ValueError(f"{name} has shape {getattr(self, name).shape}, expected {shape}")
        names = self.camera_names
        if len(set(names)) != len(names):
            raise ValueError(f"two cameras of the run have the same name: {names}")
        for camera in self.other_cameras:
            camera.validate(T)

    def warn_unplayable(self, what: str) -> None:
        """Logs a warning naming each camera's images without a finite arrival stamp,
        which ``what`` (a writer of the run in arrival order) leaves out."""
        for camera in self.cameras:
            bad = np.sort(camera.arrival_order()[1])
            if len(bad):
                log.warning("%s: %d image(s) of camera '%s' not written (%s): no finite "
                            "arrival stamp to place them at", what, len(bad), camera.name,
                            ", ".join(str(i) for i in bad[:5]) + (" ..." if len(bad) > 5
                                                                  else ""))

    def stamped_in(self, ticks_per_second: int) -> RecordedRun:
        """This run with every stamp rounded to the nearest tick of a clock with
        ``ticks_per_second`` ticks (an integer), as real sensors stamp: the nearest float
        to each integer count of ticks over ``ticks_per_second``, which is what a log of
        integer ticks read back gives."""
        per_second = int(ticks_per_second)

        def ticks(times: np.ndarray) -> np.ndarray:
            return np.round(np.asarray(times, float) * per_second) / per_second

        return dataclasses.replace(
            self, reading_times_s=ticks(self.reading_times_s),
            image_capture_times_s=ticks(self.image_capture_times_s),
            image_arrival_times_s=ticks(self.image_arrival_times_s),
            truth_times_s=ticks(self.truth_times_s),
            other_cameras=[dataclasses.replace(c, capture_times_s=ticks(c.capture_times_s),
                                               arrival_times_s=ticks(c.arrival_times_s))
                           for c in self.other_cameras])

    def stamped_in_nanoseconds(self) -> RecordedRun:
        """:meth:`stamped_in` ns, as ROS stamps: a bag of it (``io/run_bag.py``) holds
        exactly its times."""
        return self.stamped_in(10**9)

    def stamped_in_microseconds(self) -> RecordedRun:
        """:meth:`stamped_in` µs, as LCM stamps (``utime``): an LCM log of it
        (``io/run_lcm_log.py``) holds exactly its times; they are whole ns too."""
        return self.stamped_in(10**6)

    @property
    def duration_s(self) -> float:
        """The last ground-truth time (s); 0 for a run without ground truth."""
        return float(self.truth_times_s[-1]) if len(self.truth_times_s) else 0.0

    def save(self, path: str | Path) -> Path:
        """Writes the run to ``path`` as a compressed ``.npz`` (the keys of the module doc;
        ``extra`` is not stored), creating its folder; returns the path written, with ``.npz``
        appended when missing."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        np.savez_compressed(
            path,
            format_version=np.array(FORMAT_VERSION),
            robot_config_yaml=np.array(self.robot_config_yaml),
            scenario_yaml=np.array(self.scenario_yaml),
            joint_names=np.array(self.joint_names),
            reading_times_s=self.reading_times_s,
            readings_rad=self.readings_rad,
            image_capture_times_s=self.image_capture_times_s,
            image_arrival_times_s=self.image_arrival_times_s,
            depth_images_m=self.depth_images_m.astype(np.float32),
            camera_intrinsics=self.camera_intrinsics.as_array(),
            truth_times_s=self.truth_times_s,
            truth_positions_rad=self.truth_positions_rad,
            truth_bias_rad=self.truth_bias_rad,
            truth_camera_offset=self.truth_camera_offset,
            truth_X_CE=self.truth_X_CE,
            camera_names=np.array(self.camera_names),
            **self._other_camera_arrays(),
        )
        # np.savez appends .npz when missing.
        return path if path.suffix == ".npz" else path.with_name(path.name + ".npz")

    def _other_camera_arrays(self) -> dict[str, np.ndarray]:
        out = {}
        for j, camera in enumerate(self.other_cameras, 1):
            for key, name in _CAMERA_KEYS.items():
                out[f"camera{j}_{key}"] = np.asarray(getattr(camera, name))
            out[f"camera{j}_depth_images_m"] = out[f"camera{j}_depth_images_m"].astype(
                np.float32)
            out[f"camera{j}_intrinsics"] = camera.intrinsics.as_array()
        return out

    @staticmethod
    def load(path: str | Path) -> RecordedRun:
        """Reads a run written by :meth:`save`; a file that is not one raises ValueError
        naming it (FileNotFoundError when there is none)."""
        if not Path(path).is_file():
            raise FileNotFoundError(f"recorded run '{path}' does not exist")
        if not zipfile.is_zipfile(path):  # numpy would try it as a pickle
            raise ValueError(f"{path}: not a recorded run: not a .npz (zip) archive, or a "
                             f"truncated one")
        try:
            return RecordedRun._load(path)
        except (OSError, EOFError, KeyError, ValueError, zipfile.BadZipFile) as err:
            raise ValueError(f"{path}: not a readable recorded run (a .npz written by "
                             f"drake-tracker record): {type(err).__name__}: {err}") from err

    @staticmethod
    def _load(path: str | Path) -> RecordedRun:
        with np.load(path, allow_pickle=False) as data:
            version = int(data["format_version"])
            if version not in READABLE_VERSIONS:
                raise ValueError(f"{path}: format_version {version}, expected one of "
                                 f"{READABLE_VERSIONS}")
            names = [FIRST_CAMERA_NAME] if version == 1 else [
                str(n) for n in data["camera_names"]]
            others = [CameraImages(name=names[j], intrinsics=CameraIntrinsics.from_array(
                data[f"camera{j}_intrinsics"]), **{field_name: data[f"camera{j}_{key}"]
                                                   for key, field_name in _CAMERA_KEYS.items()})
                      for j in range(1, len(names))]
            return RecordedRun(
                camera_name=names[0],
                other_cameras=others,
                robot_config_yaml=str(data["robot_config_yaml"]),
                scenario_yaml=str(data["scenario_yaml"]),
                joint_names=[str(s) for s in data["joint_names"]],
                reading_times_s=data["reading_times_s"],
                readings_rad=data["readings_rad"],
                image_capture_times_s=data["image_capture_times_s"],
                image_arrival_times_s=data["image_arrival_times_s"],
                depth_images_m=data["depth_images_m"],
                camera_intrinsics=CameraIntrinsics.from_array(data["camera_intrinsics"]),
                truth_times_s=data["truth_times_s"],
                truth_positions_rad=data["truth_positions_rad"],
                truth_bias_rad=data["truth_bias_rad"],
                truth_camera_offset=data["truth_camera_offset"],
                truth_X_CE=data["truth_X_CE"],
            )
