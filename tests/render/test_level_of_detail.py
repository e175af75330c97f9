"""The likelihood's level of detail of CAD meshes, against Drake's RenderEngineVtk on the
full meshes, and the simplification's geometric tolerance."""

import numpy as np
import pytest

from drake_tracker.core.render.backends import make_renderer
from drake_tracker.core.render.batched import BatchedDepthRenderer
from drake_tracker.core.render.configurations import (
    default_view_configuration,
    random_configurations,
)
from drake_tracker.core.render.level_of_detail import LevelOfDetail, cluster_mesh, edges_balanced
from drake_tracker.core.render.meshes import sphere_mesh
from drake_tracker.core.sensors.camera import CameraIntrinsics
from drake_tracker.robot.hires import SMALL_TESSELLATION, hires_apollo_model

FULL = CameraIntrinsics.from_fov(640, 480, np.radians(45))


@pytest.fixture(scope="module")
def model(tmp_path_factory):
    return hires_apollo_model(tmp_path_factory.mktemp("hires"), **SMALL_TESSELLATION)


@pytest.mark.parametrize("stride", [8, 4], ids=["80x60", "160x120"])
def test_level_of_detail_matches_drake_vtk_on_cad_meshes(model, stride):
    intrinsics = FULL.subsampled(stride)
    renderer = BatchedDepthRenderer(model, intrinsics)
    # The level of detail must actually be coarser than the meshes it comes from.
    assert renderer.source_meshes.num_triangles >= 10_000
    assert renderer.num_triangles < 0.5 * renderer.source_meshes.num_triangles
    q = random_configurations(model, 6, seed=21, center=default_view_configuration(model))
    ours = renderer.render(q)
    ref = make_renderer(model, intrinsics, "drake").render(q)
    hit_ours, hit_ref = np.isfinite(ours), np.isfinite(ref)
    either, both = hit_ours | hit_ref, hit_ours & hit_ref
    assert both.sum() > 0.03 * ours.size  # the robot is in view
    label_agreement = 1.0 - (hit_ours ^ hit_ref).sum() / either.sum()
    diff = np.abs(ours[both].astype(float) - ref[both].astype(float))
    assert label_agreement >= 0.99, label_agreement
    assert np.median(diff) <= 0.002, np.median(diff)
    assert np.percentile(diff, 95) <= 0.010, np.percentile(diff, 95)


def test_the_likelihood_path_scores_the_images_that_match_drake_vtk(model):
    """The image update's likelihood path (8 particles at a time, core/simd/lane_render.py)
    on the CAD robot scores exactly the images compared with RenderEngineVtk above:
    its scores equal the plain likelihood of those images (to the float32 terms' stated
    tolerance)."""
    from drake_tracker.core.likelihood.pixel_model import (
        LikelihoodParams,
        log_likelihoods,
        prepare_observation,
    )
    from drake_tracker.core.render.configurations import synthetic_observation
    from drake_tracker.core.simd.lane_likelihood import SCORE_ATOL_PER_PIXEL

    renderer = BatchedDepthRenderer(model, FULL.subsampled(8))
    center = default_view_configuration(model)
    params = LikelihoodParams()
    observation = prepare_observation(synthetic_observation(renderer, center), params)
    q = random_configurations(model, 19, seed=4, spread_rad=0.05, center=center)
    images = renderer.render(q)
    expected = log_likelihoods(images, observation, params)
    assert np.ptp(expected) > 1.0
    robot_pixels = np.isfinite(images).sum(axis=(1, 2))
    assert np.all(np.abs(renderer.score(q, observation) - expected)
                  <= SCORE_ATOL_PER_PIXEL * robot_pixels)


def test_clustered_sphere_stays_within_a_cell_and_keeps_its_culling():
    radius, cell = 0.06, 0.01
    vertices, triangles = sphere_mesh(radius, 96)
    v, t = cluster_mesh(vertices, triangles, cell)
    assert len(t) < 0.25 * len(triangles)
    assert edges_balanced(triangles) and edges_balanced(t)
    # Surface points: vertices, edge midpoints and centroids of the simplified triangles;
    # the bound is the cell's diagonal (the tessellated input lies within ~0.1 mm).
    corners = v[t]
    points = np.concatenate([v, corners.mean(axis=1),
                             0.5 * (corners[:, 0] + corners[:, 1]),
                             0.5 * (corners[:, 1] + corners[:, 2])])
    error = np.abs(np.linalg.norm(points, axis=1) - radius)
    assert error.max() <= np.sqrt(3.0) * cell + 2e-4, error.max()
    # The quadric placement keeps the vertices on the surface far better than the bound.
    assert np.median(np.abs(np.linalg.norm(v, axis=1) - radius)) < 0.1 * cell
    # Triangles keep their winding: outward normals stay outward.
    normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    assert np.all(np.einsum("ij,ij->i", normals, corners.mean(axis=1)) > 0)


def test_edges_balanced_detects_an_open_mesh():
    vertices, triangles = sphere_mesh(0.05, 16)
    assert edges_balanced(triangles)
    assert not edges_balanced(triangles[1:])


def test_primitive_robots_keep_their_meshes():
    from drake_tracker.robot.model import build_tracker_model, robot_preset

    apollo = build_tracker_model(robot_preset("apollo"))
    renderer = BatchedDepthRenderer(apollo, FULL.subsampled(8))
    assert renderer.num_triangles == renderer.source_meshes.num_triangles


def test_bad_level_of_detail_is_rejected():
    with pytest.raises(ValueError, match="cell_px"):
        LevelOfDetail(cell_px=0.0)
    for bad in ({"max_disagreement": 1.0}, {"max_disagreement": -0.1},
                {"finest_cell_px": 4.0}, {"finest_cell_px": 0.0}, {"calibration_images": 0},
                {"depth_tolerance_m": 0.0}, {"reference_depth_m": -1.0},
                {"min_reduction": 0.5}):
        with pytest.raises(ValueError, match="LevelOfDetail needs"):
            LevelOfDetail(**bad)
    LevelOfDetail(max_disagreement=None, finest_cell_px=9.0)  # one cell: no ladder
    assert list(LevelOfDetail().ladder_m(FULL.subsampled(8))) == [3.0, 2.0, 1.333333,
                                                                  0.888889, 0.592593]


def test_the_cad_robots_temporary_folder_is_removed_at_exit():
    """hires_apollo_model's default folder lives as long as the process, not longer (the
    bench and the tests build it in every run: 47 folders had piled up in /tmp)."""
    import subprocess
    import sys
    from pathlib import Path

    probe = ("from drake_tracker.robot.hires import hires_apollo_model\n"
             "m = hires_apollo_model(segments=8, fillet_steps=1)\n"
             "print(m.config.model_file)\n")
    out = subprocess.run([sys.executable, "-c", probe], check=True, capture_output=True,
                         text=True).stdout.split()
    sdf = Path(out[-1])
    assert sdf.name.endswith(".sdf") and "apollo_hires_" in str(sdf)
    assert not sdf.parent.exists()
