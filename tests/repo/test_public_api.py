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


def test_the_positional_add_tracker_call_still_works_with_a_deprecation_warning(apollo):
    import numpy as np
    import pytest
    from pydrake.systems.framework import DiagramBuilder
    from pydrake.systems.primitives import ConstantValueSource, ConstantVectorSource

    from drake_tracker import AddTracker, CameraIntrinsics, DepthFrame, TrackerParams
    from drake_tracker.systems.add_tracker import ESTIMATE_PORTS

    camera = CameraIntrinsics.from_fov(80, 60, np.radians(45.0))

    def sources(builder):
        from pydrake.common.value import AbstractValue

        position = builder.AddSystem(ConstantVectorSource(
            np.zeros(len(apollo.robot_joint_names))))
        stamp = builder.AddSystem(ConstantVectorSource([0.0]))
        frame = builder.AddSystem(ConstantValueSource(AbstractValue.Make(DepthFrame.empty())))
        return position.get_output_port(), stamp.get_output_port(), frame.get_output_port()

    old = DiagramBuilder()
    q, t, depth = sources(old)
    with pytest.warns(DeprecationWarning, match="keyword"):
        systems = AddTracker(old, apollo, camera, TrackerParams(), q, t, depth, 0.01)
    new = DiagramBuilder()
    q, t, depth = sources(new)
    keyword = AddTracker(new, model=apollo, camera=camera, measured_position=q,
                         measurement_time=t, depth=depth, encoder_period_s=0.01)
    for built in (systems, keyword):
        assert built.model is apollo
        for name in (*ESTIMATE_PORTS, "health"):
            assert getattr(built, name) is built.port(name)
        assert built.X_CE.get_name() == "X_CE"
    with pytest.raises(TypeError, match="both by position and by keyword"), \
            pytest.warns(DeprecationWarning):
        AddTracker(DiagramBuilder(), apollo, model=apollo)
    with pytest.raises(TypeError, match="missing keyword"):
        AddTracker(DiagramBuilder(), model=apollo)
