"""The image update's parameters (``TrackerParams.image``) and their checks."""

import math
from dataclasses import dataclass, field

from drake_tracker.core.likelihood.pixel_model import LikelihoodParams

#: Names accepted by ``ImageParams.blocks`` besides an explicit list of joint groups.
BLOCK_MODES = ("per-joint", "arm-camera", "single", "camera")


def check_field(cond: bool, where: str, value: object, why: str) -> None:
    """Raises ValueError ``where = value: why`` unless ``cond``."""
    if not cond:
        raise ValueError(f"{where} = {value!r}: {why}")


@dataclass
class ImageParams:
    """The Coordinate Particle Filter image update."""

    #: False: images are ignored (the encoders-only method).
    enabled: bool = True
    #: Particles per block; likelihood evaluations per image = particles x blocks.
    num_particles: int = 50
    #: Particles per block until the arm is acquired (``health.acquired``); 0 =
    #: ``num_particles``. The first images search the whole initial bias prior: with 50,
    #: 6 of 6 tracker seeds of arm++/constant lost the arm, with 150 none (docs/defaults.md).
    acquisition_num_particles: int = 150
    #: ``per-joint`` (one block per joint, base to tip, then the camera offset),
    #: ``arm-camera`` (robot joints, then the 6 virtual joints), ``single``, ``camera``
    #: (only the virtual joints, one block each), or an
    #: explicit list of blocks given as joint-name lists in ``block_joints``.
    blocks: str = "per-joint"
    block_joints: list[list[str]] = field(default_factory=list)
    #: Resample when KL(weights || uniform) exceeds this (nats).
    max_kl: float = 2.0
    #: Likelihood exponents of successive CPF sweeps per image, increasing to 1; [1.0]
    #: is the paper's single sweep. Evaluations per image = particles x blocks x layers.
    annealing_betas: list[float] = field(default_factory=lambda: [0.003, 0.03, 0.3, 1.0])
    #: Images are subsampled to about this width (px) before the update (docs/method.md §4).
    image_width_px: int = 80
    #: Per annealing sweep, the width (px) of the image it scores, e.g. [20, 20, 80, 80]:
    #: the tempered sweeps only place the last one's particles (docs/method.md §4). The
    #: last must be image_width_px; empty = image_width_px for every sweep.
    sweep_image_widths_px: list[int] = field(default_factory=list)
    #: Until the arm is first held (at the start, and after a restart from the
    #: encoders), the start-up search may score each annealing sweep with every pixel's
    #: depth σ widened by this (m) times (1 - β), the last (β = 1) as it is: wider peaks
    #: lead an arm that is off by more than its own thickness in the image to the
    #: observed one. 0 (default): no widening. 0.05 tracks example-robot-data's Panda
    #: seen from 1.5 m with 8.6 deg biases and its camera 2 cm / 2 deg off, which the
    #: plain search hides behind the observed arm (417-467 mm at 1 s on 4 of 4 seeds);
    #: on the quick suite it costs more than it gains (medians over seeds: s-full-arm and
    #: arm++ with a constant bias 1.15 -> 1.42 and 1.41 -> 1.84 mm, lasting occlusion
    #: 22.9 -> 40.2; in-out-in without bias 18.5 -> 5.3): README, "A vendor's robot".
    search_depth_widening_m: float = 0.0
    #: Subtracted from each image's capture stamp to get its time t' (s).
    image_time_offset_s: float = 0.0
    #: Images closer than this to the previously processed one are skipped (s); 0 = all.
    #: 0.1 processes about 10 of a 30 Hz camera's images per second.
    min_image_interval_s: float = 0.1
    #: In a Diagram: simulated time (s) from an image's arrival to its observation, the
    #: update's compute time. > 0: the update runs on a worker thread meanwhile (the
    #: Simulator waits at the deadline if it is not done); 0: at once, in the Simulator's
    #: thread. An image due while one is in flight applies that one first.
    update_latency_s: float = 0.08
    #: ``batched`` (numba rasteriser) or ``drake`` (RenderEngineVtk, the reference).
    renderer: str = "batched"
    #: The near and far clipping planes of the particles' renderings (m).
    near_m: float = 0.1
    far_m: float = 6.0
    #: Each image's occlusion probability o is estimated (the likelihood's prior
    #: ``likelihood.occlusion_probability`` is then the prior of that estimate): the
    #: fraction of the robot's pixels, rendered at the prior mean, that the image shows
    #: hidden behind something nearer, with a Beta prior worth this many pixels. With o
    #: fixed at 0.1, an image hiding 78 % of the arm made every hidden pixel a 1-in-10
    #: event, and configurations that put the arm out of sight (0 per pixel) scored
    #: better than the truth: the estimate was dragged away (issue 17). (The switch
    #: ``estimate_occlusion`` that turned it off is gone.)
    occlusion_prior_pixels: float = 20.0
    #: A joint's bias jump is looked for only on an image with at least this many valid
    #: pixels that a jump of it (either way, by its std) would change, at the prior mean
    #: (``core/robustness/jump_visibility.py``; 0: always).
    min_jump_pixels: int = 5
    #: Seed of the particle filter's random numbers (one stream per image sequence).
    seed: int = 0
    likelihood: LikelihoodParams = field(default_factory=LikelihoodParams)



def validate_image_params(im: ImageParams) -> None:
    """Model-independent checks of ``TrackerParams.image``; raises ValueError naming the
    field."""
    check_field(im.num_particles >= 1, "image.num_particles", im.num_particles, "must be >= 1")
    check_field(im.min_jump_pixels >= 0, "image.min_jump_pixels", im.min_jump_pixels,
                "must be >= 0")
    check_field(im.acquisition_num_particles >= 0, "image.acquisition_num_particles",
                im.acquisition_num_particles, "must be >= 0 (0: image.num_particles)")
    check_field(im.blocks in BLOCK_MODES or im.blocks == "explicit", "image.blocks", im.blocks,
                f"must be one of {list(BLOCK_MODES)} or 'explicit'")
    if im.blocks == "explicit":
        check_field(len(im.block_joints) > 0, "image.block_joints", im.block_joints,
                    "must list at least one block when image.blocks is 'explicit'")
    check_field(im.max_kl > 0, "image.max_kl", im.max_kl, "must be > 0")
    check_field(math.isfinite(im.occlusion_prior_pixels) and im.occlusion_prior_pixels > 0,
                "image.occlusion_prior_pixels", im.occlusion_prior_pixels, "must be > 0")
    betas = list(im.annealing_betas)
    check_field(bool(betas) and betas[-1] == 1.0 and all(0 < b <= 1 for b in betas)
                and betas == sorted(betas), "image.annealing_betas", betas,
                "must increase within (0, 1] and end at 1.0")
    check_field(im.image_width_px >= 1, "image.image_width_px", im.image_width_px, "must be >= 1")
    check_field(not im.sweep_image_widths_px or (
        len(im.sweep_image_widths_px) == len(betas) and min(im.sweep_image_widths_px) >= 1
        and im.sweep_image_widths_px[-1] == im.image_width_px), "image.sweep_image_widths_px",
        im.sweep_image_widths_px, "must be empty, or one width >= 1 per annealing sweep "
        "ending with image.image_width_px")
    check_field(math.isfinite(im.search_depth_widening_m) and im.search_depth_widening_m >= 0,
                "image.search_depth_widening_m", im.search_depth_widening_m,
                "must be finite and >= 0 (m)")
    check_field(math.isfinite(im.image_time_offset_s), "image.image_time_offset_s",
                im.image_time_offset_s, "must be finite")
    for name in ("min_image_interval_s", "update_latency_s"):
        value = getattr(im, name)
        check_field(math.isfinite(value) and value >= 0, f"image.{name}", value,
                    "must be finite and >= 0")
    check_field(im.renderer in ("batched", "drake"), "image.renderer", im.renderer,
                "must be 'batched' or 'drake'")
    check_field(0 < im.near_m < im.far_m, "image.near_m/far_m", (im.near_m, im.far_m),
                "need 0 < near_m < far_m")
    im.likelihood.validate("image.likelihood")
    check_field(im.seed >= 0 and int(im.seed) == im.seed, "image.seed", im.seed,
                "must be an integer >= 0")
