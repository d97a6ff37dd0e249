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
    # Faces wholly above 80 % of the box's height are cut away (the icosphere's cap).
    top = box.bounds[0, 2] + viewer.CUT_HEIGHT * 3.0
    kept = int(np.sum(recon.vertices[recon.faces][:, :, 2].min(axis=1) <= top))
    assert 0 < kept < len(recon.faces)
    assert len(traces["reconstruction"]["i"]) + len(traces["walls near the camera"]["i"]) == kept
    assert np.allclose(traces["trajectory"]["x"], poses[:, 0, 3])
    assert len(traces["camera frustums"]["x"]) == 3 * 8 * 3
    assert np.allclose(traces["goals"]["z"], [1.0])


def test_cut_away_drops_the_ceiling_and_fades_the_walls_by_the_camera():
    room = trimesh.creation.box(extents=(4.0, 4.0, 3.0))
    room.apply_translation([2.0, 2.0, 1.5])
    bounds = room.bounds
    view = viewer.first_view(bounds, np.array([[3.0, 3.0, 1.5]]))
    assert np.all(view["corner"] == [-1, -1])  # the corner farthest from the path
    assert np.all((view["eye"] > bounds[0]) & (view["eye"] < bounds[1]))
    room = room.subdivide().subdivide()
    shown, faded = viewer.cut_away(room, bounds, view["corner"])
    centres = room.triangles_center
    assert not np.any(shown & (centres[:, 2] > 2.9)) and not np.any(faded & (centres[:, 2] > 2.9))
    assert np.all(np.minimum(centres[faded, 0], centres[faded, 1]) < viewer.WALL_BAND_M)
    far_walls = (centres[:, 0] > 3.9) | (centres[:, 1] > 3.9)
    assert np.all(shown[far_walls & (centres[:, 2] < 2.0)])


def test_page_of_a_full_default_scene_map_stays_under_5_mb(tmp_path):
    pytest.importorskip("plotly", reason="the viewer extra (plotly) is not installed")
    import gymnasium as gym

    import naruto_gym  # noqa: F401

    env = gym.make("NarutoRecon-v0", scene="replica_like_room", image_scale=0.25)
    base = env.unwrapped
    scene = base.scene
    # A map as dense as a 1000-step episode's (hundreds of thousands of coloured faces).
    dense = trimesh.Trimesh(scene.vertices, scene.faces, process=False).subdivide_to_size(0.03)
    dense.visual.vertex_colors = np.random.default_rng(0).integers(0, 255, (len(dense.vertices), 4))
    assert len(dense.faces) > 200_000
    turns = np.linspace(0.0, 6 * np.pi, 1001)
    poses = np.repeat(np.eye(4)[None], len(turns), axis=0)
    poses[:, 0, 3], poses[:, 1, 3], poses[:, 2, 3] = 2.5 + np.cos(turns), 2.5 + np.sin(turns), 1.4
    goals = np.random.default_rng(1).uniform(1.0, 4.0, (40, 3))
    page = viewer.write_viewer(tmp_path / "view.html", dense, scene, poses, base.camera, goals)
    env.close()
    assert page.stat().st_size <= 5_000_000
    layout = viewer.read_figure(page)["layout"]
    assert len(layout["sliders"][0]["steps"]) == viewer.SLIDER_STEPS


#: The system's Chromium (Debian's ``chromium``, which scripts/setup.sh installs for the tests)
#: and the switches it runs headless with in a container: no sandbox, no GPU, nothing fetched.
SYSTEM_CHROMIUM = "/usr/bin/chromium"
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync"]


def _browser():
    """A headless Chromium through Playwright: NARUTO_CHROMIUM's executable, else the system's
    (SYSTEM_CHROMIUM), else Playwright's own; NARUTO_CHROMIUM_ARGS adds switches. Skips only
    where Playwright is missing or there is no browser at all; a system Chromium that does not
    start fails the test."""
    import os
    from pathlib import Path

    sync_api = pytest.importorskip("playwright.sync_api", reason="playwright is not installed")
    executable = os.environ.get("NARUTO_CHROMIUM") or (
        SYSTEM_CHROMIUM if Path(SYSTEM_CHROMIUM).is_file() else None)
    manager = sync_api.sync_playwright().start()
    args = [*CHROMIUM_ARGS, *os.environ.get("NARUTO_CHROMIUM_ARGS", "").split()]
    try:
        browser = manager.chromium.launch(executable_path=executable, args=args)
    except Exception as error:  # noqa: BLE001 (no browser installed: nothing to test with)
        manager.stop()
        if executable is not None:
            raise
        pytest.skip(f"no headless Chromium could be started: {str(error).splitlines()[0]}")
    return manager, browser


def test_page_renders_in_a_headless_browser(tmp_path):
    pytest.importorskip("plotly", reason="the viewer extra (plotly) is not installed")
    manager, browser = _browser()
    box = trimesh.creation.box(extents=(4.0, 4.0, 3.0))
    box.apply_translation([2.0, 2.0, 1.5])
    recon = box.subdivide().subdivide()
    poses = np.repeat(np.eye(4)[None], 30, axis=0)
    poses[:, 0, 3] = np.linspace(1.0, 3.0, 30)
    poses[:, 1, 3], poses[:, 2, 3] = 2.0, 1.4
    page_path = viewer.write_viewer(tmp_path / "view.html", recon, box, poses,
                                    PinholeCamera().scaled(0.1), np.array([[2.0, 2.0, 1.0]]))
    try:
        page = browser.new_page(viewport={"width": 900, "height": 600})
        errors = []
        page.on("pageerror", lambda error: errors.append(str(error)))
        page.goto(page_path.as_uri())
        page.wait_for_selector("body[data-rendered=yes]", timeout=120_000)
        assert page.locator(".gl-container canvas, canvas").count() > 0
        assert page.locator(".slider-container").count() == 1
        shot = page.screenshot()
    finally:
        browser.close()
        manager.stop()
    assert not errors
    from io import BytesIO

    from PIL import Image

    picture = np.asarray(Image.open(BytesIO(shot)).convert("RGB"))
    assert picture.std() > 10  # drawn, not a blank page


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
