"""Tracker parameters that keep unit tests fast (shared by the test modules)."""

from drake_tracker.params.tracker_params import TrackerParams


def small_params() -> TrackerParams:
    """Few particles, two sweeps, every image processed: cheap image updates whose
    decisions (applied, skipped, warned) are those of the defaults."""
    p = TrackerParams()
    p.image.num_particles = 20
    p.image.annealing_betas = [0.1, 1.0]
    p.image.min_image_interval_s = 0.0
    # Every image (33 ms apart) is applied at once, as the offline tracker applies it, so
    # that a Diagram's estimates equal the offline tracker's (the latency's own test:
    # tests/systems/test_systems.py).
    p.image.update_latency_s = 0.0
    return p


def seeded_params(seed: int = 0) -> TrackerParams:
    """100 particles seeded with ``seed``, the default sweeps, every image processed (the
    offline tracker's tests and those of several cameras)."""
    params = TrackerParams()
    params.image.num_particles = 100
    params.image.seed = seed
    params.image.min_image_interval_s = 0.0
    return params
