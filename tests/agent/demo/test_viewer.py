"""The 3D view's geometry, its page read back, and the message when plotly is missing."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from naruto_agent.demo import viewer
from naruto_gym.sensors.pinhole import PinholeCamera


def test_frustum_of_an_identity_pose_spans_the_field_of_view():
    camera = PinholeCamera(width=100, height=50, fx=50.0, fy=50.0, cx=49.5, cy=24.5)
    segments = viewer.frustum_segments(np.eye(4)[None], camera, depth_m=2.0)
    assert segments.shape == (8, 2, 3)
    assert np.allclose(segments[:4, 0], 0.0)  # four spokes from the camera centre
    corners = segments[:4, 1]
    assert np.allclose(corners[:, 2], 2.0)
    # Image edges at u = -0.5 and 99.5: x = (u - cx) / fx * depth = -/+ 2.
    assert np.allclose(sorted(set(np.round(corners[:, 0], 6))), [-2.0, 2.0])
    assert np.allclose(sorted(set(np.round(corners[:, 1], 6))), [-1.0, 1.0])
    assert np.allclose(segments[4:, 0], corners)  # the rim joins the corners in turn


def test_frustums_follow_the_pose():
    camera = PinholeCamera(width=100, height=50, fx=50.0, fy=50.0, cx=49.5, cy=24.5)
    pose = np.eye(4)
    pose[:3, :3] = [[0, 0, 1], [-1, 0, 0], [0, -1, 0]]  # looking along world x
    pose[:3, 3] = [1.0, 2.0, 1.5]
    segments = viewer.frustum_segments(pose[None], camera, depth_m=0.5)
    assert np.allclose(segments[:4, 0], [1.0, 2.0, 1.5])
    assert np.allclose(segments[:4, 1, 0], 1.5)


def test_feature_edges_of_a_box_are_its_twelve_edges():
    box = trimesh.creation.box(extents=(2.0, 1.0, 1.0))
    edges = viewer.feature_edges(box.vertices, box.faces)
    assert len(edges) == 12  # the face diagonals are flat and left out
    lengths = np.sort(np.linalg.norm(edges[:, 1] - edges[:, 0], axis=1))
    assert np.allclose(lengths, [1.0] * 8 + [2.0] * 4)
    assert len(viewer.feature_edges(box.vertices, box.faces, max_edges=4)) == 4


def test_open_borders_are_outline_too():
    square = trimesh.Trimesh([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], [[0, 1, 2], [0, 2, 3]])
    assert len(viewer.feature_edges(square.vertices, square.faces)) == 4


def test_simplify_keeps_the_mesh_under_the_face_budget():
    sphere = trimesh.creation.icosphere(subdivisions=5)  # 20,480 faces
    sphere.visual.vertex_colors = np.tile([200, 100, 50, 255], (len(sphere.vertices), 1))
    simple = viewer.simplify_mesh(sphere, 2000)
    assert 0 < len(simple.faces) <= 2000
    assert np.allclose(np.linalg.norm(simple.vertices, axis=1), 1.0, atol=0.05)
    assert np.all(simple.visual.vertex_colors[:, :3] == [200, 100, 50])
    assert viewer.simplify_mesh(sphere, 50_000) is sphere


def test_written_page_reads_back(tmp_path):
    pytest.importorskip("plotly", reason="the viewer extra (plotly) is not installed")
    box = trimesh.creation.box(extents=(4.0, 4.0, 3.0))
    recon = trimesh.creation.icosphere(subdivisions=2)
    poses = np.repeat(np.eye(4)[None], 5, axis=0)
    poses[:, 0, 3] = np.linspace(0.0, 1.0, 5)
    goals = np.array([[0.5, 0.5, 1.0]])
    path = viewer.write_viewer(
        tmp_path / "view.html", recon, box, poses, PinholeCamera().scaled(0.1), goals, frustums=3
    )
    traces = viewer.read_viewer(path)
    assert tuple(traces) == viewer.TRACE_NAMES
    assert len(traces["reconstruction"]["i"]) == len(recon.faces)
    assert np.allclose(traces["trajectory"]["x"], poses[:, 0, 3])
    assert len(traces["camera frustums"]["x"]) == 3 * 8 * 3
    assert np.allclose(traces["goals"]["z"], [1.0])


def test_missing_plotly_skips_the_page_with_a_message(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(viewer, "plotly_available", lambda: False)
    box = trimesh.creation.box()
    page = viewer.write_viewer(tmp_path / "view.html", box, box, np.eye(4)[None], PinholeCamera())
    assert page is None and not (tmp_path / "view.html").exists()
    assert 'pip install "naruto-gym[viewer]"' in capsys.readouterr().out


def test_read_viewer_refuses_a_page_without_a_figure(tmp_path):
    page = tmp_path / "other.html"
    page.write_text("<html><body>no figure</body></html>")
    with pytest.raises(ValueError, match="no plotly figure"):
        viewer.read_viewer(page)
