"""The public API: every name in ``drake_tracker.__all__`` imports and is documented."""

import drake_tracker


def test_public_names_import_and_have_docstrings():
    from drake_tracker import (  # noqa: F401  (the names the README promises)
        AddTracker,
        CpfImageUpdateSystem,
        DelayBufferSystem,
        JointKalmanBankSystem,
        RobotConfig,
        Tracker,
        TrackerParams,
        build_tracker_model,
    )

    undocumented = [name for name in drake_tracker.__all__ if name != "__version__"
                    and not (getattr(drake_tracker, name).__doc__ or "").strip()]
    assert undocumented == []
    assert {"AddTracker", "Tracker", "TrackerParams", "RobotConfig", "build_tracker_model",
            "JointKalmanBankSystem", "DelayBufferSystem",
            "CpfImageUpdateSystem"} <= set(drake_tracker.__all__)


def test_unknown_names_raise_attribute_error():
    try:
        drake_tracker.NoSuchThing  # noqa: B018
    except AttributeError as err:
        assert "NoSuchThing" in str(err)
    else:
        raise AssertionError("drake_tracker.NoSuchThing did not raise")
