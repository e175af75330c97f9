"""Fixtures shared by the test modules."""

import pytest

from drake_tracker.robot.model import build_tracker_model, robot_preset


@pytest.fixture(scope="session")
def apollo():
    """The default robot (Apollo's arm and head, with the six virtual camera joints):
    built once for the whole session; tests must not modify it."""
    return build_tracker_model(robot_preset("apollo"))
