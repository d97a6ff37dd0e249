"""The main job writes the pictures, the coverage curve and a summary."""

import json

from naruto_gym.demo import main


def test_demo_writes_outputs(tmp_path):
    main(["--steps", "12", "--picture-every", "6", "--image-scale", "0.1", "--out", str(tmp_path)])
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["steps"] == 12
    assert 0.0 < summary["coverage"] <= 1.0
    for name in ("frame_0006.png", "frame_0012.png", "coverage.png", "coverage.csv"):
        assert (tmp_path / name).stat().st_size > 0
    rows = (tmp_path / "coverage.csv").read_text().strip().splitlines()
    assert len(rows) == 1 + 13
