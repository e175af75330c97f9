"""The tracker's health: is each image consistent with the estimate, and is it tracking?

Before each image update the robot is rendered once at the belief's mean at the image's
time (what the filter expects to see: a predictive check, the image-space analogue of a
normalised innovation) and compared, pixel by pixel, with the image:

* ``robot_pixels``: pixels where the estimate shows the robot and the image is valid;
* ``agreement``: the fraction of those whose depth is within 3σ (pixel noise) of it;
* ``see_through``: the fraction where the camera sees *behind* the estimated robot, by
  more than 3σ and ``SEE_THROUGH_MARGIN_M``. An occluder only ever makes the image
  nearer than the robot, so seeing through it means the robot is not where the
  estimate puts it: the one disagreement that occlusion cannot explain;
* ``occluded``: the fraction where the image is nearer than the robot by more than 3σ
  (something in front of it).

:class:`HealthMonitor` turns the per-image figures into a state:

* ``tracking``: the latest images agree with the estimate;
* ``uncertain``: the latest image saw too little of the robot to say (fewer than
  ``min_robot_pixels`` unoccluded robot pixels: out of view, or hidden), or one image
  disagreed, or it sees through none of the arm but confirms too little of it
  (``tracking_agreement``: an estimate centimetres off, or an arm partly hidden), or
  the images agree but the estimate's biases are implausible (a challenger belief is
  out, ``core/robustness/second_opinion.py``): a wrong fold can explain the
  images, as example-robot-data's Panda showed, its arm hidden behind the observed one
  with 99 % of its unhidden pixels agreeing;
* ``lost``: ``images_in_a_row`` consecutive images disagreed (``see_through`` above
  ``max_see_through``): the images keep contradicting the belief, and the filter has not
  re-acquired (one image that shows a bias step and is followed at once is one
  disagreement). A controller should fall back to the encoders.

The state returns to ``tracking`` after ``images_in_a_row`` consistent images.
"""


import enum
from dataclasses import dataclass, replace

import numpy as np

from drake_tracker.core.likelihood.pixel_model import LikelihoodParams, pixel_sigma, valid_pixels
from drake_tracker.core.robustness.innovation import (
    Innovation,
    image_inconsistent,
    innovations_consistent,
    with_innovation,
)

#: Depth behind the estimated robot that counts as seeing through it, besides 3σ (m).
SEE_THROUGH_MARGIN_M = 0.02


class HealthState(enum.IntEnum):
    """What a controller should make of the estimate."""

    TRACKING = 0
    UNCERTAIN = 1
    LOST = 2


@dataclass(frozen=True)
class ImageConsistency:
    """How one image compares with the estimate at its time."""

    time_s: float
    robot_pixels: int
    agreement: float
    see_through: float
    occluded: float = 0.0

    @property
    def visible_robot_pixels(self) -> float:
        """Robot pixels that the image does not show hidden behind something."""
        return self.robot_pixels * (1.0 - self.occluded)

    @property
    def mostly_hidden(self) -> bool:
        """More of the rendered arm hidden than unhidden (a vote; ``occluded > 0.5``)."""
        return 2.0 * self.occluded > 1.0


def image_consistency(time_s: float, rendered_m: np.ndarray, observed_m: np.ndarray,
                      params: LikelihoodParams) -> ImageConsistency:
    """Compares the estimate's rendered depth (inf: no robot) with the observed image (same
    shape, NaN/0: invalid)."""
    rendered_m = np.asarray(rendered_m, float)
    observed_m = np.asarray(observed_m, float)
    if rendered_m.shape != observed_m.shape:
        raise ValueError(f"rendered {rendered_m.shape} and observed {observed_m.shape} "
                         f"images differ in shape")
    robot = np.isfinite(rendered_m) & valid_pixels(observed_m, params)
    count = int(robot.sum())
    if count == 0:
        return ImageConsistency(float(time_s), 0, 0.0, 0.0, 0.0)
    z, d = observed_m[robot], rendered_m[robot]
    sigma = pixel_sigma(z, params)
    agree = np.abs(z - d) <= 3.0 * sigma
    behind = z > d + 3.0 * sigma + SEE_THROUGH_MARGIN_M
    nearer = z < d - 3.0 * sigma
    return ImageConsistency(float(time_s), count, float(agree.mean()), float(behind.mean()),
                            float(nearer.mean()))


@dataclass
class HealthParams:
    """Thresholds of the health state; loadable from YAML."""

    #: Fewer robot pixels than this (at the processing resolution) say nothing.
    min_robot_pixels: int = 30
    #: An image disagrees when more than this fraction of the robot is seen through.
    max_see_through: float = 0.25
    #: Images in a row that change the state or the course: disagreeing ones before
    #: ``lost`` (0.2 s at 10 images/s), consistent ones before ``tracking`` again,
    #: confirming ones before ``tracking`` is reported (``tracking_agreement``), and
    #: surprising ones before a second opinion (``is_surprising``). One
    #: image is never evidence enough: a bias step looks like a surprising image, and
    #: the bias-jump prior follows it in that image.
    images_in_a_row: int = 2
    #: The longest the tracker holds a belief that no image confirms (s). The arm counts
    #: as acquired (``TrackerHealth.acquired``) while a ``tracking`` image came within it;
    #: after longer out of view or hidden, the images that see it again are a new search
    #: (``image.acquisition_num_particles``, no bias jumps): on in-out-in with a
    #: time-varying bias, the arm came back 150 mm from the estimate after 4 s out of
    #: view, and 50 particles put it behind the scene (0.8 m). And the belief restarts
    #: from the encoders once the images have shown the estimate's arm out of view, and
    #: the encoders' in view, for as long: see ``ImageProcessor.restart_reason`` in
    #: ``core/image_processor.py``. A challenger belief (``Challenger``) searches as
    #: long, then rests as long. (Retired keys it replaces: ``params/yaml_fields.py``.)
    max_unconfirmed_s: float = 1.0
    #: The margin, in nats per valid pixel of the image: the log-likelihood sums over
    #: the valid pixels, so a margin that does not scale with them means a different
    #: test at every resolution. 0.021: 100 nats at the quick suite's 4,730 valid
    #: pixels (80 x 60), the fixed margin it replaces.
    second_opinion_margin_nats_per_pixel: float = 0.021
    #: The state is reported ``tracking`` only while the latest ``images_in_a_row``
    #: images each confirm (agree with, within 3σ of the pixel noise) at least this
    #: fraction of the robot pixels the estimate renders on valid image pixels
    #: (``confirms``); a pixel the image shows hidden confirms nothing, so an arm partly
    #: hidden is ``uncertain``. At 678a4b4, on the quick suite's 130 recorded runs, both
    #: tracker streams: ``tracking`` within 10 mm on 99.6 % of the images that say it,
    #: none of the images over 50 mm off saying it (docs/evaluation.md). Reported only:
    #: a controller that needs the arm (``servo``) stops at ``lost``, not ``uncertain``.
    tracking_agreement: float = 0.95

    def validate(self) -> None:
        """Raises ValueError naming the field."""
        checks = (
            ("min_robot_pixels", self.min_robot_pixels >= 1, "must be >= 1"),
            ("max_see_through", 0 < self.max_see_through < 1, "must be in (0, 1)"),
            ("images_in_a_row", self.images_in_a_row >= 1, "must be >= 1"),
            ("max_unconfirmed_s", self.max_unconfirmed_s > 0, "must be > 0"),
            ("second_opinion_margin_nats_per_pixel",
             0 <= self.second_opinion_margin_nats_per_pixel < 1e3, "must be in [0, 1e3)"),
            ("tracking_agreement", 0 <= self.tracking_agreement <= 1,
             "must be in [0, 1] (0: see-through alone decides)"),
        )
        for name, ok, why in checks:
            if not ok:
                raise ValueError(f"health.{name} = {getattr(self, name)!r}: {why}")


@dataclass(frozen=True)
class Challenger:
    """A second belief about the angles, held relative to the encoders' arm (so it
    follows the readings between images, as a bias does): angle ``offset_mean`` (n,)
    and ``offset_var`` (rad, rad^2) from the restart's mean; ``time_s``, the image time
    of its latest update; ``images``, the images it has seen; ``started_s``, the image
    time of its first (default ``time_s``). It searches for
    ``HealthParams.max_unconfirmed_s``, the longest the tracker holds a belief that no
    image confirms, then rests as long (no search: a robot whose biases really are that
    large pays at most half the time), then may start again."""

    offset_mean: np.ndarray
    offset_var: np.ndarray
    time_s: float
    images: int = 0
    #: (n,) the camera offset it searches from, the estimate's at its start (virtual
    #: joints; NaN elsewhere: ``Restart.pinned_angle``).
    pinned_angle: np.ndarray | None = None
    started_s: float | None = None

    def __post_init__(self) -> None:
        if self.started_s is None:
            object.__setattr__(self, "started_s", self.time_s)


@dataclass(frozen=True)
class TrackerHealth:
    """The health state after the latest image, and that image's consistency."""

    state: HealthState = HealthState.UNCERTAIN
    latest: ImageConsistency | None = None
    disagreeing_in_a_row: int = 0
    agreeing_in_a_row: int = 0
    #: Time of the latest image that found the tracker ``tracking`` (s).
    confirmed_s: float = -float("inf")
    #: Whether an image confirmed the estimate (``tracking``) within
    #: ``HealthParams.max_unconfirmed_s``: the tracker holds the arm.
    acquired: bool = False
    #: Times the belief was restarted from the encoders (``ImageOutcome.restarted``).
    restarts: int = 0
    #: Since when the images have shown the estimate's arm out of view and the encoders'
    #: in view (``is_misplaced``; inf: the latest image did not).
    misplaced_since_s: float = float("inf")
    #: The challenger belief, while one searches or rests (``core/robustness/second_opinion.py``).
    challenger: Challenger | None = None
    #: The latest applied images' innovations (``core/robustness/innovation.py``).
    innovations: tuple[Innovation, ...] = ()
    #: Images in a row, the latest included, that confirm the estimate (``confirms``).
    confirming_in_a_row: int = 0
    #: Images in a row, the latest included, that contradict most of the estimate's
    #: unhidden arm (``contradicts``).
    surprising_in_a_row: int = 0

    def in_a_row(self, count: int, params: HealthParams) -> bool:
        """Whether ``count`` images before this one, with this one, make
        ``images_in_a_row`` (always, before the first image: there is nothing before it
        to ask)."""
        return self.latest is None or count + 1 >= params.images_in_a_row

    def tracked(self, params: HealthParams) -> bool:
        """The health's own ``tracking``: ``images_in_a_row`` consistent images in a row
        at least, whatever the report's stricter tests (``tracking_agreement``, the
        innovations) made of ``state``."""
        return self.agreeing_in_a_row >= params.images_in_a_row


def is_consistent(image: ImageConsistency, params: HealthParams) -> bool:
    """Whether an image sees enough of the rendered arm (``min_robot_pixels``) and does
    not see through it (``max_see_through``)."""
    return bool(image.visible_robot_pixels >= params.min_robot_pixels
                and image.see_through <= params.max_see_through)


def agreeing_pixels(image: ImageConsistency) -> float:
    """Robot pixels whose depth agrees with the rendered arm's."""
    return image.agreement * image.robot_pixels


def confirms(image: ImageConsistency, params: HealthParams) -> bool:
    """Whether an image agrees with the estimate on at least ``tracking_agreement`` of
    the robot pixels the estimate renders (those it shows hidden confirm nothing)."""
    return agreeing_pixels(image) >= params.tracking_agreement * image.robot_pixels


def shows_no_arm(estimate: ImageConsistency, encoders: ImageConsistency,
                 health: TrackerHealth, params: HealthParams) -> bool:
    """Whether an image, while the arm is acquired, shows nothing where the estimate
    puts the arm nor where the encoders do: each rendering has at least
    ``min_robot_pixels``, and the image sees behind it on all of them but fewer than
    ``min_robot_pixels`` (too few to say anything about the arm). No arm, and nothing in
    front of one: no bias can explain it (a moved camera, a stale or foreign frame).
    Before acquisition (a start from a wrong bias) such images are the search's.

    It replaces a fraction of its own, ``no_arm_see_through`` (0.9 of both seen
    through). Measured against a rule that also skipped images seeing through more than
    ``max_see_through`` of both with fewer than ``min_robot_pixels`` agreeing (the rest
    nearer than the arm): on the quick suite's random-walk-6 that rule skipped images in
    which both arms were 40-50 deg off and the true arm stood in front of them, and seed
    1 went from 215 to 929 mm."""
    return bool(health.acquired and all(
        image.robot_pixels >= params.min_robot_pixels
        and image.robot_pixels * (1.0 - image.see_through) < params.min_robot_pixels
        for image in (estimate, encoders)))


def contradicts(image: ImageConsistency, params: HealthParams) -> bool:
    """Whether an image contradicts most of the arm where the estimate puts it: of the
    robot pixels it does not show hidden (at least ``min_robot_pixels``), more disagree
    with the estimate's depth than agree (a vote: no fraction to tune).

    It replaces ``second_opinion_agreement`` (0.5, the same rule as a number), whose
    other values were worse (``docs/method.md`` §7, the retired table)."""
    visible = image.visible_robot_pixels
    # agreeing < visible - agreeing, written so that it is exact in floating point
    return visible >= params.min_robot_pixels and 2 * agreeing_pixels(image) < visible


def is_surprising(image: ImageConsistency, params: HealthParams,
                  health: TrackerHealth | None = None) -> bool:
    """Whether an image ``contradicts`` the estimate and, with ``health`` (the state
    after the images before it), closes ``images_in_a_row`` such images in a row: one
    is what a bias step looks like, and the bias-jump prior follows it in that image;
    more in a row mean the update did not."""
    return contradicts(image, params) and (
        health is None or health.in_a_row(health.surprising_in_a_row, params))


def drifts(image: ImageConsistency, health: TrackerHealth, params: HealthParams) -> bool:
    """Whether the tracked belief may lag a bias that moves faster than its model: the
    latest applied image's innovation failed the filter's consistency test on its own
    (``innovation.image_inconsistent``), and this image does not confirm the arm it
    shows unhidden (fewer than ``tracking_agreement`` of those pixels agree). H2, the
    kept search, is then asked (``EncoderSearch.kept_search``). Measured on the quick
    suite (``docs/method.md`` §7): the window's test instead stays failed five images
    after one large innovation, and searching on each image after an inconsistent one
    regardless of this image cost 14 % of the update against 10 %. A second opinion
    of its own."""
    visible = image.visible_robot_pixels
    if not health.innovations:
        return False
    return image_inconsistent(health.innovations[-1]) and (
        visible >= params.min_robot_pixels
        and agreeing_pixels(image) < params.tracking_agreement * visible)


def confirms_more(image: ImageConsistency, other: ImageConsistency,
                  params: HealthParams) -> bool:
    """Whether an image agrees with one rendered arm (``image``) on at least
    ``min_robot_pixels``, and on more pixels than with another (``other``)."""
    agreeing = agreeing_pixels(image)
    return agreeing >= params.min_robot_pixels and agreeing > agreeing_pixels(other)


def is_misplaced(estimate: ImageConsistency, encoders: ImageConsistency,
                 params: HealthParams, health: TrackerHealth | None = None) -> bool:
    """Whether an image finds the encoders' arm (zero bias) in view and the estimate's
    (mostly) out of it: the estimate renders fewer robot pixels (on valid image pixels)
    than ``min_robot_pixels`` or than half the encoders' (most of the arm the encoders
    put in view is out of it: a vote, no fraction to tune), and the image does not show
    the estimate's arm more than the encoders' (``confirms_more``). A
    rendered size is not evidence: a bias that drifted far can swing the encoders' arm
    towards the camera, where it renders twice the true arm's pixels. A belief no image
    has confirmed (``health.confirmed_s``: since the start or a restart) counts only its
    unhidden pixels while the encoders' arm shows ``min_robot_pixels`` unhidden: a
    start-up search put the arm behind the real one (560 pixels, all hidden) and held it
    8.5 s, 400 mm off (quick suite, in-out-in/constant seed 0, tracker stream 100). Once
    confirmed, a hidden arm is an occlusion, and its belief is kept.

    The half replaces ``misplaced_fraction`` (0.5, the same rule as a number; at 0.3
    in-out-in/constant's worst seed went 44.8 -> 446 mm). Measured on s-head-arm/
    time-varying seed 0: after a bias step the estimate turned the head away from the
    arm over 5 s, each image agreeing with what it still rendered (97 %), 789 -> 343
    robot pixels against the encoders' 782, 770 mm off."""
    shown = estimate.robot_pixels
    if health is not None and not np.isfinite(health.confirmed_s) and (
            encoders.visible_robot_pixels >= params.min_robot_pixels):
        shown = estimate.visible_robot_pixels
    out = shown < params.min_robot_pixels or 2 * shown < encoders.robot_pixels
    return encoders.robot_pixels >= params.min_robot_pixels and out and (
        not confirms_more(estimate, encoders, params))


def restart_due(health: TrackerHealth, time_s: float, params: HealthParams) -> bool:
    """Whether the estimate has been misplaced for ``max_unconfirmed_s`` at
    ``time_s`` (an image that is misplaced too)."""
    return time_s - health.misplaced_since_s >= params.max_unconfirmed_s


def next_health(health: TrackerHealth, image: ImageConsistency, params: HealthParams,
                restarted: bool = False, misplaced: bool = False,
                challenger: Challenger | None = None,
                innovation: Innovation | None = None) -> TrackerHealth:
    """The health after one more image (a pure function, so the Drake system can keep
    its state in the Context); ``restarted``: the belief was restarted from the encoders
    before this image's update (``image`` then compares it with the restarted belief),
    which forgets that the arm was acquired; ``misplaced``: see ``is_misplaced``;
    ``challenger``: the challenger belief after this image; ``innovation``: the joint
    filter's innovation of this image's observation (``innovation.image_innovation``;
    None: the image was not applied, and the state comes from its pixels alone)."""
    if restarted:
        health = replace(health, confirmed_s=-float("inf"), disagreeing_in_a_row=0,
                         restarts=health.restarts + 1)
    if image.visible_robot_pixels < params.min_robot_pixels:
        state = HealthState.LOST if health.state == HealthState.LOST else HealthState.UNCERTAIN
        bad, good = health.disagreeing_in_a_row, 0
    elif image.see_through > params.max_see_through:
        bad, good = health.disagreeing_in_a_row + 1, 0
        state = HealthState.LOST if bad >= params.images_in_a_row else \
            max(health.state, HealthState.UNCERTAIN)
    else:
        bad, good = 0, health.agreeing_in_a_row + 1
        if health.state == HealthState.TRACKING or good >= params.images_in_a_row:
            state = HealthState.TRACKING
        else:
            state = health.state
    confirmed_s = image.time_s if state == HealthState.TRACKING else health.confirmed_s
    acquired = image.time_s - confirmed_s <= params.max_unconfirmed_s
    since = min(health.misplaced_since_s, image.time_s) if misplaced else float("inf")
    confirming = health.confirming_in_a_row + 1 if confirms(image, params) else 0
    surprising = health.surprising_in_a_row + 1 if contradicts(image, params) else 0
    confirmed = confirming > 0 and health.in_a_row(health.confirming_in_a_row, params)
    if state == HealthState.TRACKING and (challenger is not None or not confirmed):
        # The image does not see through the estimate, but does not confirm it either
        # (``tracking_agreement``), or it does while the estimate's biases are
        # implausible: it may be a wrong fold that explains them. Reported only: the arm
        # still counts as confirmed (``confirmed_s``, ``acquired``) and the next image's
        # state does not depend on it (an internal TRACKING has at least
        # ``images_in_a_row`` agreeing images in a row).
        state = HealthState.UNCERTAIN
    innovations = health.innovations
    if innovation is not None:
        innovations = with_innovation(innovations, innovation)
        if state == HealthState.TRACKING and not innovations_consistent(innovations):
            # The images agree with the estimate, but the filter's innovations are larger
            # than its model allows (a bias stepping or drifting faster than its model,
            # a wrong mode being followed): reported only, like the case above.
            state = HealthState.UNCERTAIN
    return TrackerHealth(state, image, bad, good, confirmed_s, acquired, health.restarts, since,
                         challenger, innovations, confirming, surprising)
