"""The robot with CAD-like meshes used by the bench and the level-of-detail tests.

Apollo's links, joints and frames with every visual an OBJ mesh as a CAD export gives it
(``write_apollo_hires`` in ``models/generate_hires.py``): 54,720 triangles by default,
about 19k with the small settings the tests use. Written on demand into a folder (a
temporary one by default), so no large mesh files are shipped.
"""

from __future__ import annotations

import atexit
import dataclasses
import shutil
import tempfile
from pathlib import Path

from drake_tracker.models.generate_hires import write_apollo_hires
from drake_tracker.robot.model import TrackerModel, build_tracker_model, robot_preset

#: Tessellation of the bench's real-mesh robot (>= 40k triangles) and of the tests' one.
BENCH_TESSELLATION = {"segments": 96, "fillet_steps": 5}
SMALL_TESSELLATION = {"segments": 48, "fillet_steps": 3}


def hires_apollo_model(folder: str | Path | None = None, segments: int = 96,
                       fillet_steps: int = 5) -> TrackerModel:
    """The tracker model of Apollo with CAD-like OBJ meshes written into ``folder``
    (default: a new temporary folder, kept for the life of the process and removed at its
    exit)."""
    if folder is None:
        folder = tempfile.mkdtemp(prefix="apollo_hires_")
        atexit.register(shutil.rmtree, folder, ignore_errors=True)
    sdf = write_apollo_hires(Path(folder), segments=segments, fillet_steps=fillet_steps)
    config = dataclasses.replace(robot_preset("apollo"), model_file=str(sdf))
    return build_tracker_model(config)
