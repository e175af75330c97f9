"""Recorded runs in and out: the run format, replay through the offline tracker, synthetic runs."""
