"""The restart that keeps what the image does not contradict (issue 43, item 2).

A restart (H1 of ``docs/method.md`` §7) forgets every bias and the camera offset: each
angle back at its reading at zero bias, the camera at its nominal mount. When the image
contradicts only part of the belief (one joint's bias gone wrong), that throws away what
the other joints had learnt, and the search after it has to find their biases again.

Measured on the full protocol's both/time-varying seed 6: after a bias step the update did
not follow, the full restart left the hand 200-280 mm off for 2.4 s; the partial one,
keeping every robot joint but arm joint 1 and the camera offset (log-likelihood 507
against -1,384), 3-7 mm within 0.4 s (``docs/method.md`` §7).

So the restart is chosen among a family of partial restarts: a set of robot joints and,
optionally, the camera's offset joints restart, and every other joint keeps its mean
with the bias step of ``Restart.kept`` (its variance inflated, not reset). Each member is
scored by the image's log-likelihood ℓ at its mean, the one currency of the searches
(``EncoderSearch._beats``), and a partial member replaces the full restart only when

    ℓ(member) > max(ℓ(full restart), 0) + m N,

m = ``health.second_opinion_margin_nats_per_pixel`` and N the image's valid pixels: it
explains the image better than the full restart and than no arm at all (ℓ = 0: the
likelihood scores only the pixels where a configuration puts the robot), each by the
margin. Measured without the 0 (but never for a belief no image had confirmed; the
quick suite's 130 recorded runs, both tracker streams, 2026-11-30): a member kept a bias
that an earlier search had put out of view, ℓ -1,686 against the full restart's -2,131,
and the arm came back 85-131 mm off for a second instead of at once (arm++/constant
seed 0, stream 100: median from 5 s 1.56 -> 2.25 mm). Only members whose rendered arm
``fits`` count: one that keeps the arm out of view would score 0 and beat every arm in
view that the image does not fit.

The family, over the k robot joints a restart touches (in the model's order, base to
tip), each with the camera offset restarted or kept: every joint alone, every joint but
one, every chain's prefix (base to a joint) and suffix (a joint to the tip): at most
2 (4 k + 1) members, rendered in one batch.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

from drake_tracker.core.filter.angle_observation import Restart
from drake_tracker.core.filter.kalman import MEAN_A
from drake_tracker.core.robustness.health import (
    HealthParams,
    ImageConsistency,
    is_consistent,
    is_misplaced,
)

if TYPE_CHECKING:
    from drake_tracker.core.cpf.image_update import CpfImageUpdate
    from drake_tracker.core.likelihood.pixel_model import PreparedObservation


def restarted_sets(count: int) -> list[tuple[int, ...]]:
    """The sets of positions among ``count`` chained joints that a partial restart
    restarts (each non-empty, none twice, the full set first): every joint alone, every
    joint but one, every prefix and every suffix."""
    every = tuple(range(count))
    sets = [every]
    for j in range(count):
        for members in ((j,), every[:j] + every[j + 1:], every[: j + 1], every[j:]):
            if members and members not in sets:
                sets.append(members)
    return sets


def restart_family(restart: Restart, robot: np.ndarray, camera: np.ndarray
                   ) -> list[Restart]:
    """The partial restarts of ``restart``, the full one first: ``robot`` (indices, base
    to tip) are the robot joints it restarts, ``camera`` the offset joints it returns to
    the mount; a member restarts one of ``restarted_sets`` of ``robot`` and either all of
    ``camera`` or none, and keeps the rest (``Restart.keeping``)."""
    robot, camera = np.asarray(robot, np.int64), np.asarray(camera, np.int64)
    family = []
    for members in restarted_sets(len(robot)):
        kept = np.setdiff1d(robot, robot[list(members)])
        family.append(restart.keeping(kept))
        if len(camera):
            family.append(restart.keeping(np.concatenate([kept, camera])))
    if not len(robot) and len(camera):
        family = [restart, restart.keeping(camera)]
    return family or [restart]


def fits(image: ImageConsistency, encoders: ImageConsistency, params: HealthParams) -> bool:
    """Whether a partial restart's arm may replace the encoders' arm (``encoders``, the
    full restart's): the image (``image``, its consistency with that arm) is consistent
    with it and does not find it misplaced."""
    return is_consistent(image, params) and not is_misplaced(image, encoders, params)


def least_restart(update: CpfImageUpdate, restart: Restart, family: list[Restart],
                  prior: np.ndarray, plain: PreparedObservation, margin_nats_per_pixel: float,
                  admissible: Callable[[np.ndarray], bool]
                  ) -> tuple[Restart, np.ndarray, np.ndarray]:
    """The member of ``family`` (the full ``restart`` first) to restart ``prior`` with on
    the image ``plain`` (prepared without the occlusion estimate), the image's
    log-likelihood at each member's mean (-inf: not admissible) and the chosen member's
    rendered depth (inf where no robot): the best-scoring partial member if it beats the
    full restart and no arm at all (0 nats) by ``margin_nats_per_pixel`` per valid
    pixel, else the full one. Only
    members whose rendered arm is ``admissible`` count: the likelihood scores only the
    pixels where a configuration puts the robot, so a member that keeps an arm out of
    view (or hidden) would score 0 nats and beat any arm in view that the image does not
    fit exactly."""
    means = np.stack([member.apply(prior)[MEAN_A] for member in family])
    rendered = update.renderer.render(means)
    ok = np.array([True] + [admissible(depth) for depth in rendered[1:]])
    scores = np.full(len(family), -np.inf)
    scores[ok] = update.log_likelihood(means[ok], plain)
    best = int(np.argmax(scores[1:])) + 1 if len(family) > 1 else 0
    if best and scores[best] > max(scores[0], 0.0) + margin_nats_per_pixel * plain.num_valid:
        return family[best], scores, rendered[best]
    return restart, scores, rendered[0]


def kept_note(restart: Restart, scores: np.ndarray) -> str:
    """The log's note on a restart that keeps joints (none: "")."""
    if restart.kept_joints is None:
        return ""
    return (f", keeping joints {restart.kept_joints.tolist()} (log-likelihood "
            f"{np.max(scores):.0f} against {scores[0]:.0f} for a full restart)")
