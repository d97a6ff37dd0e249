"""Episode records on disk: one JSON file per episode, written atomically.

A record is written to a temporary file in the same folder, flushed to disk, then renamed
over the final name (``os.replace`` is atomic on POSIX and Windows), so a reader (or a rerun
after a crash or Ctrl-C) sees either the whole old record, the whole new one, or none.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

STATUS_OK = "ok"
STATUS_FAILED = "failed"


def _jsonable(value: Any) -> Any:
    """Plain-JSON copy of records holding numpy values; NaN/inf become None."""
    if isinstance(value, dict):
        return {str(key): _jsonable(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(item) for item in value]
    if isinstance(value, np.ndarray):
        return _jsonable(value.tolist())
    if isinstance(value, np.generic):
        return _jsonable(value.item())
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, Path):
        return str(value)
    return value


def write_json_atomic(path: str | Path, data: Any) -> Path:
    """Write ``data`` as JSON to ``path`` atomically (temporary file + rename)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    handle, temporary = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(handle, "w") as stream:
            json.dump(_jsonable(data), stream, indent=1)
            stream.flush()
            os.fsync(stream.fileno())
        os.chmod(temporary, 0o644)  # mkstemp makes it private; records are for everyone
        os.replace(temporary, path)
    except BaseException:
        Path(temporary).unlink(missing_ok=True)
        raise
    return path


def read_record(path: str | Path) -> dict[str, Any] | None:
    """A stored record, or None when the file is missing or unreadable."""
    try:
        with open(path) as stream:
            record = json.load(stream)
    except (OSError, ValueError):
        return None
    return record if isinstance(record, dict) else None


def is_done(path: str | Path, config_hash: str) -> bool:
    """True when ``path`` holds a successful record made with the same settings."""
    record = read_record(path)
    return (
        record is not None
        and record.get("status") == STATUS_OK
        and record.get("config_hash") == config_hash
    )


def source_commit() -> str | None:
    """The commit of the source tree that makes the records, when it is a git checkout (None
    otherwise): the provenance a record or a run keeps."""
    root = Path(__file__).resolve().parents[2]
    try:
        result = subprocess.run(
            ["git", "-C", str(root), "rev-parse", "--short", "HEAD"],
            capture_output=True,
            text=True,
            timeout=10,
            check=False,
        )
    except (OSError, subprocess.SubprocessError):
        return None
    return result.stdout.strip() or None if result.returncode == 0 else None


def load_records(output_dir: str | Path) -> list[dict[str, Any]]:
    """Every readable record under ``output_dir/records`` (sorted by episode id)."""
    records = []
    for path in sorted((Path(output_dir) / "records").glob("*/*/*.json")):
        record = read_record(path)
        if record is not None and "episode_id" in record:
            records.append(record)
    return sorted(records, key=lambda record: record["episode_id"])
