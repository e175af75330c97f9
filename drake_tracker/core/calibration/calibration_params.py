"""The parameters of the cameras' calibration while the tracker runs (``online.py``)."""

import math
from dataclasses import dataclass


@dataclass
class SelfCalibrationParams:
    """With several cameras whose offsets are estimated (``estimate_camera_offset``)
    and not given (``camera_offsets``), the tracker fits them once to a window of every
    camera's images and holds them (``core/calibration/online.py``)."""

    #: The window's length (s): the first this long, after every camera has said
    #: ``tracking``, in which each camera has 3 images that show the arm. 0: the tracker
    #: does not calibrate its cameras. Measured (two-camera presets, 2-core Zen 4 VM):
    #: 1 s and 2 s give the same accuracy at the presets' own length (whole-run p50
    #: 1.7-2.6 and 1.8-2.7 mm in the blind camera's frame), and in the quick suite's
    #: 10 s 1 s calibrates in time where 2 s mostly does not (in-out-in-2cam 2.1-4.4
    #: against 3.8-14.4 mm).
    window_s: float = 1.0
    #: The fit's evaluations of the window's log-likelihood (20 images): the time the
    #: image that completes the window takes, about 0.25 ms each on a Zen 4 core with
    #: 80 x 60 images (8000: 1.9-2.3 s).
    max_evaluations: int = 8000

    def validate(self) -> None:
        """Raises ValueError naming the field."""
        if not (math.isfinite(self.window_s) and self.window_s >= 0):
            raise ValueError(f"camera_calibration.window_s = {self.window_s!r}: must be "
                             "finite and >= 0 (0: no calibration while tracking)")
        if not (isinstance(self.max_evaluations, int) and self.max_evaluations >= 24):
            raise ValueError(f"camera_calibration.max_evaluations = "
                             f"{self.max_evaluations!r}: must be an integer >= 24 (one "
                             "generation of the search)")
