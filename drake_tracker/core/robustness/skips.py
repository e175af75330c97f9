"""Why an image of one of several cameras is not applied: the text a skipped image
carries (``ImageOutcome.skip_reason``), which the health counts and the log shows."""

from __future__ import annotations

from drake_tracker.core.robustness.health import HealthParams, ImageConsistency


def out_of_view_reason(camera_name: str | None, predicted: ImageConsistency,
                       params: HealthParams) -> str:
    """Why an image of one of several cameras that shows fewer than
    ``params.min_robot_pixels`` of the arm unhidden where the estimate puts it is not
    applied. Such an image only says where the arm is not, and the posterior is pushed
    away from the view, onto the joints only this camera sees (its offsets, a pan-tilt
    head): on in-out-in-2cam/none seed 0 the head camera's pose drifted 0.5 to 4.4 deg in
    5 s with the hand out of its view (the hand in its frame 1 to 97 mm off). With one
    camera its restart and out-of-view logic use that information.

    Nor one that shows more of the arm hidden than unhidden while another camera tracks
    it. Measured on occlusion-lasting-2cam at its full 30 s: the head camera's first
    images of the arm coming out from behind the plate (33-165 unhidden pixels) pinned its
    pose 1.2 deg off; its later images then moved the arm 8-31 deg a joint, the post
    camera's moved it back, and the head camera ended 10-30 deg off (the hand 450-890 mm
    off in its frame; docs/evaluation.md)."""
    if predicted.visible_robot_pixels >= params.min_robot_pixels:
        return (f"camera '{camera_name}' sees {predicted.occluded:.0%} of the arm hidden "
                f"where the estimate puts it, while another camera tracks it: the other "
                f"cameras hold the arm")
    return (f"camera '{camera_name}' sees {predicted.visible_robot_pixels:.0f} unhidden "
            f"robot pixels where the estimate puts the arm (fewer than "
            f"{params.min_robot_pixels}): the other cameras hold the arm")
