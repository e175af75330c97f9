"""Fixtures shared by the test modules."""

import pytest

from drake_tracker.robot.model import build_tracker_model, robot_preset


@pytest.fixture(scope="session")
def apollo():
    """The default robot (Apollo's arm and head, with the six virtual camera joints):
    built once for the whole session; tests must not modify it."""
    return build_tracker_model(robot_preset("apollo"))


@pytest.fixture
def no_challenger(monkeypatch):
    """The challenger switched off for one test (it has no parameter to: it is part of
    the per-image decision, docs/method.md section 7)."""
    from drake_tracker.core.robustness.second_opinion import EncoderSearch

    monkeypatch.setattr(EncoderSearch, "challenge", lambda self, *args: (None, None))


@pytest.fixture
def no_second_opinion():
    """The second opinion switched off for one test (``switches.second_opinion_off``)."""
    from switches import second_opinion_off

    with second_opinion_off():
        yield
