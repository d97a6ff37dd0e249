"""The harness given bad input: a damaged record file is re-run, not fatal; an unknown scene
or policy name stops the run before any episode starts."""

from __future__ import annotations

import json

import pytest
from hypothesis import given
from hypothesis import strategies as st

from naruto_agent.benchmark import build_specs, pending_specs, run_local
from naruto_agent.benchmark.cli import main
from naruto_agent.benchmark.records import is_done, read_record

TINY = {
    "image_scale": 0.05,
    "eval_points": 0,
    "eval_samples": 2000,
    "checkpoint_samples": 1000,
    "env_kwargs": {"panorama_shape": [16, 32], "coverage_samples": 500},
}


@given(content=st.one_of(st.binary(max_size=64), st.text(max_size=64).map(str.encode),
                         st.sampled_from([b"[]", b"null", b"{", b'{"status": "ok"', b"42"])))
def test_any_damaged_record_reads_as_not_done(tmp_path_factory, content):
    path = tmp_path_factory.mktemp("records") / "record.json"
    path.write_bytes(content)
    record = read_record(path)
    assert record is None or isinstance(record, dict)
    assert not is_done(path, "some-hash") or json.loads(content)["config_hash"] == "some-hash"


@pytest.mark.parametrize("damage", ["truncate", "not_json"])  # more kinds: the test above
def test_a_damaged_record_is_run_again(tmp_path, damage):
    specs = build_specs(["two_rooms"], ["random"], [0], 3, **TINY)
    assert run_local(specs, tmp_path, workers=0, progress=False) == 0
    path = specs[0].record_path(tmp_path)
    text = path.read_text()
    path.write_text({"truncate": text[: len(text) // 2], "not_json": "not json at all",
                     "empty": "", "a_list": "[1, 2]"}[damage])
    assert pending_specs(specs, tmp_path) == specs
    assert run_local(pending_specs(specs, tmp_path), tmp_path, workers=0, progress=False) == 0
    assert is_done(path, specs[0].config_hash)


@pytest.mark.parametrize(
    ("argument", "message"),
    [(["--scenes", "two_roomz"], "unknown scene"),
     (["--scenes", "two_rooms:no_roof"], "unknown scan opening"),
     (["--scenes", "procedural:castle:3"], "unknown procedural scene"),
     (["--scenes", "procedural:room"], "stream"),
     (["--policies", "narutoo"], "unknown policy"),
     (["--policies", "random", "no_such_module:Policy"], "cannot import")],
)
def test_an_unknown_name_stops_the_run_before_any_episode(tmp_path, capsys, argument, message):
    out_dir = tmp_path / "run"
    code = main(["--output-dir", str(out_dir), "--max-episode-steps", "2", "--workers", "0",
                 "--no-progress", "--no-plots", *argument])
    assert code == 2
    assert message in capsys.readouterr().err
    assert not (out_dir / "records").exists()
