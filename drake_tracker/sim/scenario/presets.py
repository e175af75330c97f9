"""Named scenario presets, ``SEQUENCE/BIAS``, after the paper's experiments.

BIAS is ``none``, ``constant`` (8.6 deg on every arm joint), ``time-varying`` (smooth
steps of alternating sign, 5 deg amplitude, so jumps reach 10 deg), ``ramp`` (0 to
8.6 deg linearly over the first 10 s on every arm joint, then held) or
``random-walk-R`` (R = 1, 3, 6: every arm joint's bias drifts from 0 as an independent
random walk of R deg/sqrt(s), seeded by the scenario: the default filter's bias model
is 1.15 deg/sqrt(s)). Sequences, all on
Apollo:

* 30 s sinusoids: ``s-lower-arm`` (elbow and wrist), ``s-upper-arm`` (shoulder),
  ``s-full-arm``, ``s-head``, ``s-head-arm``;
* 60 s smooth random motion: ``arm``, ``arm++`` (fast), ``both`` (arm and head),
  ``both++``, ``in-out-in`` (the hand leaves the view and comes back), ``occlusion`` (a
  box moves between the camera and the moving arm for most of the run);
* ``static``: 30 s, the robot holds its home pose (a sanity check: only the bias and
  the camera offset make errors);
* ``occlusion-heavy``: ``s-full-arm`` with a large box fixed in the world between the
  camera and the upper arm from 25 % to 75 % of the run (most of the arm hidden for
  15 s, then revealed); ``occlusion-lasting``: the same box from 25 % to the end;
  ``occlusion-lasting-2cam``, ``in-out-in-2cam``: those with a second camera on a post
  on the other side of the arm (``second_camera``);
* ``s-full-arm-mismatch``: ``s-full-arm`` where the world's robot is not the tracker's
  model (``MISMATCH``: joint origins 3 mm / 0.3 deg off, a cable along the arm, a hand
  15 % larger). The suffix ``-mismatch`` applies to any sequence.
"""

import copy
import dataclasses
import math

from drake_tracker.robot.model import FrameOffset
from drake_tracker.sim.scenario.config import (
    CameraConfig,
    ModelMismatchConfig,
    MountedCameraConfig,
    OccluderSpec,
    Scenario,
)
from drake_tracker.sim.scenario.profiles import ROBOT_PROFILES

#: Suffix of a sequence whose world robot differs from the tracker's model.
MISMATCH_SUFFIX = "-mismatch"
#: The world-model mismatch of the ``-mismatch`` sequences.
MISMATCH = ModelMismatchConfig(joint_origin_mm=3.0, joint_origin_deg=0.3, cable=True,
                               hand_scale=1.15, seed=1)
#: The paper's twelve sequences (the evaluation's full protocol).
SEQUENCES = ("s-lower-arm", "s-upper-arm", "s-full-arm", "s-head", "s-head-arm",
             "arm", "arm++", "both", "both++", "in-out-in", "occlusion", "static")
#: A sequence with this suffix has a second camera (``second_camera``).
TWO_CAMERA_SUFFIX = "-2cam"
#: The sequences that come with a second camera.
TWO_CAMERA_SEQUENCES = ("occlusion-lasting", "in-out-in")
#: Sequences beyond the paper's: heavy occlusion, a world that is not the model, and
#: two cameras.
EXTRA_SEQUENCES = ("occlusion-heavy", "occlusion-lasting", "s-full-arm" + MISMATCH_SUFFIX,
                   *(q + TWO_CAMERA_SUFFIX for q in TWO_CAMERA_SEQUENCES))
#: Every listed sequence (any of BASE_SEQUENCES + MISMATCH_SUFFIX is accepted too).
ALL_SEQUENCES = SEQUENCES + EXTRA_SEQUENCES
BASE_SEQUENCES = SEQUENCES + ("occlusion-heavy", "occlusion-lasting")
#: The random walks' rates (deg/sqrt(s)): the bias presets ``random-walk-R``.
RANDOM_WALK_RATES = {"random-walk-1": 1.0, "random-walk-3": 3.0, "random-walk-6": 6.0}
BIAS_VARIANTS = ("none", "constant", "time-varying", "ramp", *RANDOM_WALK_RATES)
#: When the occlusion-heavy/-lasting box enters and (heavy) leaves, as run fractions.
HEAVY_OCCLUSION_WINDOW = (0.25, 0.75)


def heavy_occluder(duration_s: float, lasting: bool) -> OccluderSpec:
    """A 4 x 26 x 26 cm plate fixed in the world 35 cm in front of Apollo's camera, facing
    it, between the camera and the upper arm (it hides 74-97 % of the arm's pixels of
    ``s-full-arm``), from 25 % of ``duration_s`` to 75 % (or to the end)."""
    enter, leave = HEAVY_OCCLUSION_WINDOW
    return OccluderSpec(shape="box", size_m=[0.04, 0.26, 0.26], motion="world",
                        xyz_m=[0.396, -0.061, 1.209], rpy_deg=[0.0, 29.3, 0.0],
                        enter_s=enter * duration_s,
                        leave_s=float("inf") if lasting else leave * duration_s,
                        rgba=[0.3, 0.3, 0.8, 1.0])


def second_camera(first: CameraConfig) -> MountedCameraConfig:
    """A camera on a post on the other side of Apollo's arm: 1.2 m ahead, 1.45 m to its
    right and 1.45 m up, looking at (0.45, -0.5, 0.9) m, where it sees the arm in front
    of the head camera's occluder and when the arm swings out of the head camera's view;
    the head camera's sensor, with a mounting error of its own."""
    camera = MountedCameraConfig(**dataclasses.asdict(first))
    camera.name = "post_camera"
    camera.mount = FrameOffset(parent="torso", xyz_m=[1.2, -1.45, 1.45],
                               rpy_deg=[-114.44, 0.0, 38.29])
    camera.offset = [-0.015, 0.02, -0.01, math.radians(-1.5), math.radians(1.0),
                     math.radians(2.0)]
    camera.offset_gain_per_rad = {}
    return camera


def _sequence_scenario(s: Scenario, sequence: str) -> None:
    p = ROBOT_PROFILES["apollo.sdf"]
    t = s.trajectory
    sinusoid_joints = {
        "s-lower-arm": p.lower_arm,
        "s-upper-arm": p.upper_arm,
        "s-full-arm": p.arm,
        "s-head": p.head,
        "s-head-arm": p.arm + p.head,
        "occlusion-heavy": p.arm,
        "occlusion-lasting": p.arm,
    }
    if sequence in sinusoid_joints:
        t.kind = "sinusoid"
        t.joints = list(sinusoid_joints[sequence])
        t.amplitude_deg = 10.0 if sequence == "s-head" else 15.0
        if sequence.startswith("occlusion-"):
            s.occluders = [heavy_occluder(s.duration_s, sequence == "occlusion-lasting")]
    elif sequence == "static":
        t.kind = "static"
    else:
        s.duration_s = 60.0
        t.kind = "free"
        t.amplitude_deg = 15.0
        t.joints = list(p.arm + p.head) if sequence.startswith("both") else list(p.arm)
        if sequence.endswith("++"):
            t.speed_scale = 2.5
        if sequence == "in-out-in":
            t.kind = "in-out-in"
            t.excursion_joint = "arm_joint_1"
            t.excursion_deg = -100.0
        if sequence == "occlusion":
            s.occluder.enabled = True


def _preset(sequence: str, bias: str) -> Scenario:
    p = ROBOT_PROFILES["apollo.sdf"]
    s = Scenario(name=f"{sequence}/{bias}", robot="apollo", duration_s=30.0)
    s.camera.offset_gain_per_rad = copy.deepcopy(p.offset_gain_per_rad)
    base = sequence.removesuffix(MISMATCH_SUFFIX).removesuffix(TWO_CAMERA_SUFFIX)
    _sequence_scenario(s, base)
    if sequence.endswith(TWO_CAMERA_SUFFIX):
        head = MountedCameraConfig(**dataclasses.asdict(s.camera))
        s.cameras = [head, second_camera(s.camera)]
    if sequence.endswith(MISMATCH_SUFFIX):
        s.model_mismatch = dataclasses.replace(MISMATCH)
    e = s.encoders
    if bias in RANDOM_WALK_RATES:
        e.bias = "random-walk"
        e.random_walk_sigma_deg_per_sqrt_s = RANDOM_WALK_RATES[bias]
    else:
        e.bias = {"none": "none", "constant": "constant", "time-varying": "steps",
                  "ramp": "ramp"}[bias]
    return s


def list_presets() -> list[str]:
    """All listed preset names, ``SEQUENCE/BIAS``."""
    return [f"{q}/{b}" for q in ALL_SEQUENCES for b in BIAS_VARIANTS]


def preset_scenario(name: str) -> Scenario:
    """A fresh copy of a named preset; unknown names raise ValueError listing the known."""
    seq, _, bias = name.partition("/")
    known_sequence = seq.removesuffix(MISMATCH_SUFFIX) in BASE_SEQUENCES or (
        seq.removesuffix(TWO_CAMERA_SUFFIX) in TWO_CAMERA_SEQUENCES)
    if not known_sequence or bias not in BIAS_VARIANTS:
        raise ValueError(f"unknown scenario preset '{name}'; known presets: {list_presets()} "
                         f"(and any SEQUENCE{MISMATCH_SUFFIX}/BIAS)")
    return _preset(seq, bias)
