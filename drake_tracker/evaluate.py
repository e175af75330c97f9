"""Kept for existing imports: the evaluation lives in :mod:`drake_tracker.evaluation`."""

from drake_tracker.evaluation import *  # noqa: F403
from drake_tracker.evaluation import __all__  # noqa: F401
