"""Laying out a scene folder: links to the dataset's files, or copies, replacing what was
there (:func:`naruto_gym.scenes.scene_folders.link_or_copy`)."""

from __future__ import annotations

from naruto_gym.scenes.scene_folders import link_or_copy


def test_a_file_is_linked_or_copied_and_replaces_what_was_there(tmp_path):
    mesh = tmp_path / "dataset" / "room_mesh.ply"
    mesh.parent.mkdir()
    mesh.write_text("mesh")
    folder = tmp_path / "scene"
    folder.mkdir()
    (folder / "mesh.ply").write_text("stale")
    link_or_copy(mesh, folder / "mesh.ply")
    assert (folder / "mesh.ply").is_symlink()
    assert (folder / "mesh.ply").resolve() == mesh.resolve()
    link_or_copy(mesh, folder / "mesh.ply", copy=True)
    assert not (folder / "mesh.ply").is_symlink()
    assert (folder / "mesh.ply").read_text() == "mesh"
    mesh.write_text("changed")
    assert (folder / "mesh.ply").read_text() == "mesh"  # a copy stands alone


def test_a_folder_is_linked_even_when_files_are_copied_and_replaces_a_folder(tmp_path):
    frames = tmp_path / "dataset" / "results"
    frames.mkdir(parents=True)
    (frames / "frame000000.jpg").write_bytes(b"jpg")
    stale = tmp_path / "scene" / "frames"
    stale.mkdir(parents=True)
    (stale / "old.jpg").write_bytes(b"old")
    link_or_copy(frames, stale, copy=True)
    assert stale.is_symlink()
    assert sorted(path.name for path in stale.iterdir()) == ["frame000000.jpg"]
