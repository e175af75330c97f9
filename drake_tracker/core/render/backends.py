"""Choosing a depth renderer backend: the numba batched rasteriser, or Drake's
RenderEngineVtk (the reference) behind the same ``render``/``score`` interface."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from drake_tracker.core.likelihood.pixel_model import score_images
from drake_tracker.core.render.batched import BatchedDepthRenderer
from drake_tracker.core.render.drake_reference import DrakeDepthRenderer
from drake_tracker.core.sensors.camera import CameraIntrinsics

if TYPE_CHECKING:
    from drake_tracker.core.likelihood.pixel_model import PreparedObservation
    from drake_tracker.robot.model import TrackerModel

#: Known backends: the numba batched rasteriser, and Drake's RenderEngineVtk (reference).
BACKENDS = ("batched", "drake")


class RenderThenScore:
    """Gives an image-only renderer (Drake's) the scoring entry point of the batched one:
    ``score(q, observation)`` renders the (N, H, W) images, then scores them with the
    plain likelihood (:func:`~drake_tracker.core.likelihood.pixel_model.score_images`)."""

    def __init__(self, renderer: DrakeDepthRenderer) -> None:
        self.renderer = renderer
        self.model = renderer.model
        self.intrinsics = renderer.intrinsics
        self.near_m = renderer.near_m
        self.far_m = renderer.far_m

    def render(self, q: np.ndarray) -> np.ndarray:
        """(N, H, W) float32 depth images of configurations q (N, nq), inf = no hit."""
        return self.renderer.render(q)

    def score(self, q: np.ndarray, observation: PreparedObservation) -> np.ndarray:
        """(N,) log-likelihoods of configurations q (N, nq) against ``observation``."""
        return score_images(self.render(q), observation)


def make_renderer(model: TrackerModel, intrinsics: CameraIntrinsics, backend: str = "batched",
                  near_m: float = 0.1, far_m: float = 6.0
                  ) -> BatchedDepthRenderer | RenderThenScore:
    """A renderer with ``render(q: (N, nq)) -> (N, H, W) float32`` (inf = no hit) and
    ``score(q, observation) -> (N,)`` log-likelihoods against a
    :class:`~drake_tracker.core.likelihood.pixel_model.PreparedObservation` of its image size."""
    if backend == "batched":
        return BatchedDepthRenderer(model, intrinsics, near_m=near_m, far_m=far_m)
    if backend == "drake":
        return RenderThenScore(DrakeDepthRenderer(model, intrinsics, near_m=near_m,
                                                  far_m=far_m))
    raise ValueError(f"unknown renderer backend '{backend}'; known: {list(BACKENDS)}")
