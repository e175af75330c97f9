"""Choosing a depth renderer backend, and timing the backends against each other."""

from __future__ import annotations

import time

import numpy as np

from drake_tracker.core.camera import CameraIntrinsics

#: Known backends: the numba batched rasteriser, and Drake's RenderEngineVtk (reference).
BACKENDS = ("batched", "drake")


def make_renderer(model, intrinsics: CameraIntrinsics, backend: str = "batched",
                  near_m: float = 0.1, far_m: float = 6.0):
    """A renderer with ``render(q: (N, nq)) -> (N, H, W) float32`` (inf = no hit)."""
    if backend == "batched":
        from drake_tracker.core.render_batched import BatchedDepthRenderer

        return BatchedDepthRenderer(model, intrinsics, near_m=near_m, far_m=far_m)
    if backend == "drake":
        from drake_tracker.core.render_drake import DrakeDepthRenderer

        return DrakeDepthRenderer(model, intrinsics, near_m=near_m, far_m=far_m)
    raise ValueError(f"unknown renderer backend '{backend}'; known: {list(BACKENDS)}")


def random_configurations(model, num: int, seed: int, spread_rad: float = 0.3,
                          center: np.ndarray | None = None) -> np.ndarray:
    """``num`` configurations around ``center`` (default: all zeros), robot joints
    perturbed by N(0, spread_rad^2) and clipped to the joint limits, virtual camera joints
    by small offsets (1 cm, 0.01 rad)."""
    from drake_tracker.robot import VIRTUAL_JOINT_NAMES

    rng = np.random.default_rng(seed)
    plant = model.plant
    nq = plant.num_positions()
    center = np.zeros(nq) if center is None else np.asarray(center, float)
    q = center + rng.normal(0.0, spread_rad, size=(num, nq))
    for name in VIRTUAL_JOINT_NAMES:
        k = model.joint_names.index(name)
        q[:, k] = center[k] + rng.normal(0.0, 0.01, size=num)
    return np.clip(q, plant.GetPositionLowerLimits(), plant.GetPositionUpperLimits())


def default_view_configuration(model) -> np.ndarray:
    """A configuration that puts the arm in the camera's view for the shipped robots:
    Apollo's head turned to the arm (pan -0.35, tilt 0.6) with the arm reaching
    forward; other robots at zero."""
    q = np.zeros(model.plant.num_positions())
    values = {"head_pan": -0.35, "head_tilt": 0.6, "arm_joint_2": 1.0, "arm_joint_4": -1.2}
    for name, value in values.items():
        if name in model.joint_names:
            q[model.joint_names.index(name)] = value
    return q


def benchmark_renderers(model, intrinsics: CameraIntrinsics, num_particles: int = 2000,
                        seed: int = 0, num_drake: int | None = None,
                        near_m: float = 0.1, far_m: float = 6.0) -> dict:
    """Renders the same random configurations with both backends in this process.

    The batched backend renders all ``num_particles`` in one call (after a warm-up that
    compiles the numba kernel); Drake renders the first ``num_drake`` of them (default
    min(num_particles, 100)) one call each. Per-image times are in microseconds.
    """
    if num_particles < 1:
        raise ValueError(f"num_particles must be >= 1, got {num_particles}")
    num_drake = min(num_particles, 100) if num_drake is None else min(num_drake, num_particles)
    q = random_configurations(model, num_particles, seed,
                              center=default_view_configuration(model))
    batched = make_renderer(model, intrinsics, "batched", near_m, far_m)
    drake = make_renderer(model, intrinsics, "drake", near_m, far_m)
    batched.render(q[:2])  # compile / load the cached kernel
    drake.render(q[:1])  # create the render window
    t0 = time.perf_counter()
    images_b = batched.render(q)
    t_batched = time.perf_counter() - t0
    t0 = time.perf_counter()
    images_d = drake.render(q[:num_drake])
    t_drake = time.perf_counter() - t0
    us_b = 1e6 * t_batched / num_particles
    us_d = 1e6 * t_drake / num_drake
    hit_b = np.isfinite(images_b[:num_drake])
    hit_d = np.isfinite(images_d)
    either = hit_b | hit_d
    return {
        "width": intrinsics.width,
        "height": intrinsics.height,
        "num_particles": num_particles,
        "num_drake_particles": num_drake,
        "num_triangles": batched.num_triangles,
        "batched_us_per_image": us_b,
        "drake_us_per_image": us_d,
        "renderer_speedup_vs_drake": us_d / us_b,
        "hit_mismatch_fraction": float((hit_b ^ hit_d).sum() / max(1, either.sum())),
        "coverage_fraction": float(hit_b.mean()),
    }
