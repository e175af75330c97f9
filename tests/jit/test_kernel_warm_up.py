"""The kernels are loaded before a simulation (drake_tracker/kernel_warm_up.py)."""

import subprocess
import sys

CHECK = """
import numpy as np
from drake_tracker.core.cpf import compiled as cpf_compiled
from drake_tracker.core.likelihood import occlusion
from drake_tracker.core.sensors.camera import CameraIntrinsics
from drake_tracker.kernel_warm_up import warm_up_tracker_kernels
from drake_tracker.params.tracker_params import TrackerParams
from drake_tracker.robot.model import build_tracker_model, robot_preset

kernels = (cpf_compiled._sweep, occlusion._surface_steps)
before = [bool(k.signatures) for k in kernels]
model = build_tracker_model(robot_preset("apollo"))
camera = CameraIntrinsics.from_fov(80, 60, np.radians(45.0))
seconds = warm_up_tracker_kernels(model, camera, TrackerParams())
print(before, [bool(k.signatures) for k in kernels], seconds > 0)
"""


def test_the_warm_up_loads_the_image_update_kernels_in_a_fresh_process():
    # A process of its own: in this one, earlier tests may have run the kernels already.
    out = subprocess.run([sys.executable, "-c", CHECK], capture_output=True, text=True,
                         check=True, timeout=600).stdout.strip().splitlines()[-1]
    # the compiled sweeps (and the scoring kernel they call) and the occlusion
    # estimate's growth: not loaded before, compiled or loaded from numba's cache after
    assert out == "[False, False] [True, True] True"
