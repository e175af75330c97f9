"""The cameras of an input with several (a bag's depth topics, an LCM log's image
channels): each a camera of the model by name, its images from a source of its own."""

from __future__ import annotations

from collections.abc import Sequence


def check_camera_sources(names: Sequence[str | None], sources: Sequence[str], what: str,
                         model_cameras: list[str] | None = None) -> None:
    """ValueError for a camera the model does not have (with ``model_cameras``, the
    model's camera names), two cameras of one name, or one source (``what``: e.g.
    ``depth topic``) for two cameras."""
    names = list(names)
    for name in names:
        if model_cameras is not None and name not in model_cameras:
            raise ValueError(f"unknown camera '{name}': the model's cameras are "
                             f"{model_cameras} (RobotConfig.cameras)")
        if names.count(name) > 1:
            raise ValueError(f"two cameras are named '{name}': give each {what} once")
    sources = list(sources)
    twice = sorted({s for s in sources if sources.count(s) > 1})
    if twice:
        raise ValueError(f"{what} {twice[0]} is given for two cameras")
