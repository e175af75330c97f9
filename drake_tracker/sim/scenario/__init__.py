"""Scenarios: the dataclasses, their checks, the named presets and shortening."""
