"""Regenerate the shipped catalogue scenes in ``envs_assets/`` (deterministic).

Writes one binary PLY per catalogue scene plus ``catalogue.json``; running it twice gives
byte-identical files. ``--check`` only verifies that the files on disk match what the
generator makes now (exit status 1 if not), which CI can run after generator changes.

    python scripts/generate_scenes.py            # (re)write envs_assets/
    python scripts/generate_scenes.py --check    # verify, write nothing
"""

from __future__ import annotations

import argparse
import dataclasses
import hashlib
import json
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

from tqdm import tqdm

from naruto_gym.scenes.catalogue import (
    CATALOGUE_FILE,
    PLY_COMMENT,
    available_scenes,
    catalogue_document,
    catalogue_entry,
)
from naruto_gym.scenes.procedural import scene_to_ply_bytes


@dataclass
class Args:
    output_dir: str = str(Path(__file__).resolve().parents[1] / "envs_assets")
    """folder that receives the PLY files and catalogue.json"""
    names: list[str] = field(default_factory=available_scenes)
    """catalogue scenes to write (default: all)"""
    check: bool = False
    """verify the existing files instead of writing them"""


def parse_args() -> Args:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    for item in dataclasses.fields(Args):
        default = item.default_factory() if callable(item.default_factory) else item.default
        flag = f"--{item.name.replace('_', '-')}"
        if item.type in (bool, "bool"):
            parser.add_argument(flag, action="store_true", default=default)
        elif item.name == "names":
            parser.add_argument(flag, nargs="+", default=default, choices=available_scenes())
        else:
            parser.add_argument(flag, type=str, default=default)
    return Args(**vars(parser.parse_args()))


def main() -> int:
    args = parse_args()
    output = Path(args.output_dir)
    output.mkdir(parents=True, exist_ok=True)
    problems = []
    for name in tqdm(args.names, desc="scenes"):
        entry = catalogue_entry(name)
        started = time.perf_counter()
        scene = entry.generate()
        data = scene_to_ply_bytes(scene, comment=PLY_COMMENT)
        seconds = time.perf_counter() - started
        path = output / entry.file
        if args.check:
            if not path.is_file() or path.read_bytes() != data:
                problems.append(f"{path} differs from the generator's output")
        else:
            path.write_bytes(data)
        tqdm.write(
            f"{name:20s} {len(scene.faces):7d} triangles  {len(data) / 1e6:5.2f} MB  "
            f"extents {scene.extents.round(2).tolist()}  generated in {seconds:.2f} s  "
            f"sha256 {hashlib.sha256(data).hexdigest()[:12]}"
        )
    document = json.dumps(catalogue_document(), indent=2) + "\n"
    json_path = output / CATALOGUE_FILE
    if args.check:
        if not json_path.is_file() or json_path.read_text(encoding="utf-8") != document:
            problems.append(f"{json_path} differs from the generator's output")
    else:
        json_path.write_text(document, encoding="utf-8")
    for problem in problems:
        print(f"MISMATCH: {problem}; run python scripts/generate_scenes.py", file=sys.stderr)
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
