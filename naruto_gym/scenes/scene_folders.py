"""Laying out a scene folder from a dataset's files: each file a link to the dataset's copy.

``scripts/prepare_replica.py`` and ``scripts/prepare_mp3d.py`` put a dataset's meshes,
trajectories and frames into the folder layout the harness reads (``mesh.ply``,
``mesh_culled.ply``, ``ground_truth.json``, ...). A link keeps the dataset's gigabytes in one
place; a copy serves a folder that must stand alone, and a file system without symbolic
links.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path


def link_or_copy(target: Path, link: Path, copy: bool = False) -> None:
    """Make ``link`` a symbolic link to ``target``, replacing whatever ``link`` was.

    Args:
        target: the dataset's file or folder.
        link: where it goes in the scene folder.
        copy: copy a file instead of linking it (a folder is always linked where links
            exist). Where the file system has no symbolic links, files and folders are
            copied whatever ``copy`` says.
    """
    target, link = Path(target), Path(link)
    if link.is_symlink() or link.is_file():
        link.unlink()
    elif link.is_dir():
        shutil.rmtree(link)
    if copy and target.is_file():
        shutil.copyfile(target, link)
        return
    try:
        os.symlink(target.resolve(), link, target_is_directory=target.is_dir())
    except OSError:  # no symbolic links here (some Windows set-ups): copy instead
        if target.is_dir():
            shutil.copytree(target, link)
        else:
            shutil.copyfile(target, link)
