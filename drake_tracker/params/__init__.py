"""The tracker's parameters: dataclasses loaded from YAML (``load_tracker_params``),
checked in one place (``validate_tracker_params``) and resolved once against a model
(``resolve_tracker_params``) into the ``ResolvedParams`` that the core reads."""

from drake_tracker.core.cpf.image_params import ImageParams
from drake_tracker.core.likelihood.pixel_model import LikelihoodParams
from drake_tracker.core.resolved_params import ResolvedParams
from drake_tracker.core.robustness.health import HealthParams
from drake_tracker.core.sensors.stamp_params import TimestampParams
from drake_tracker.params.loading import load_tracker_params, tracker_params_to_yaml
from drake_tracker.params.resolve import resolve_tracker_params
from drake_tracker.params.tracker_params import JointNoise, KalmanConfig, TrackerParams
from drake_tracker.params.validation import validate_tracker_params

__all__ = ["HealthParams", "ImageParams", "JointNoise", "KalmanConfig", "LikelihoodParams",
           "ResolvedParams", "TimestampParams", "TrackerParams", "load_tracker_params",
           "resolve_tracker_params", "tracker_params_to_yaml", "validate_tracker_params"]
