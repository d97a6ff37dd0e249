"""``naruto-benchmark --suite test --size-class external``: a folder of the user's own scans run
as a class of its own, beside the generated ones, and its section of the leaderboard."""

from __future__ import annotations

import pytest

from naruto_agent.benchmark.cli import main
from naruto_agent.benchmark.leaderboard import leaderboard_markdown
from naruto_agent.benchmark.records import load_records
from naruto_agent.benchmark.suite import read_manifest
from tests.agent.benchmark.test_suite_run import TINY
from tests.scenes.test_external_track import write_room


def test_a_folder_of_scans_runs_as_the_external_class_and_gets_its_section(tmp_path):
    scans = tmp_path / "my_scans"
    write_room(scans / "scene0000_00_vh_clean_2.ply", "z", seed=1)
    write_room(scans / "office" / "mesh.glb", "y", seed=2, size=(4.0, 3.0, 2.5))
    out = tmp_path / "run"
    common = ["--policies", "random", "--workers", "0", *TINY, "--output-dir", str(out)]
    assert main(["--suite", "test", "--size-class", "small", "--suite-limit", "1", *common]) == 0
    assert main(["--suite", "test", "--size-class", "external", "--scenes-dir", str(scans),
                 *common]) == 0  # fmt: skip
    manifest = read_manifest(out)
    external = {label: entry for label, entry in manifest["scenes"].items()
                if entry["size_class"] == "external"}  # fmt: skip
    assert sorted(entry["scene"].rsplit("@", 1)[1] for entry in external.values()) == ["y", "z"]
    assert {entry["variant"] for entry in external.values()} == {"scan"}
    records = load_records(out)
    assert len(records) == 3 and all(record["status"] == "ok" for record in records)
    page = leaderboard_markdown(out, tmp_path / "img")
    assert "## small" in page and "## external" in page and "## external (" not in page
    assert "Stalled steps" in page and "Refusals" in page


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--suite", "test", "--size-class", "small", "--scenes-dir", "x"],
         "add --size-class external"),
        (["--suite", "train", "--size-class", "external"], "test scenes only"),
        (["--suite", "test", "--size-class", "external", "--scenes-dir", "no/such/folder"],
         "does not exist"),
    ],
)  # fmt: skip
def test_bad_external_flags_say_what_to_do(argv, message, tmp_path, capsys):
    assert main([*argv, "--policies", "random", "--output-dir", str(tmp_path)]) == 2
    assert message in capsys.readouterr().err
