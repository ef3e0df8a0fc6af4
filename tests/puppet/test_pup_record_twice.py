"""Two shows started with the same --record file: the second is refused in one line, and the take
the first is recording is neither truncated nor moved from under it (it used to be kept aside as
NAME.1.jsonl while still being written, and the first show reported the wrong file)."""

from __future__ import annotations

from pathlib import Path

import pytest

from puppet.errors import ConfigError
from puppet.session import SessionWriter, keep_previous


def test_a_take_being_recorded_is_not_taken_over(tmp_path: Path) -> None:
    path = tmp_path / "show.jsonl"
    first = SessionWriter(path, {"channels": ["jaw"]}, fsync_seconds=None)
    try:
        first.values(0, [0.25])
        first.tick(1)
        before = path.read_bytes()
        assert before
        with pytest.raises(ConfigError, match="another show is recording"):
            keep_previous(path)
        with pytest.raises(ConfigError, match="another show is recording"):
            SessionWriter(path, {"channels": ["jaw"]}, fsync_seconds=None)
        assert path.read_bytes() == before and not (tmp_path / "show.1.jsonl").exists()
    finally:
        first.close(1)
    kept = keep_previous(path)  # once the show is over, its take is kept aside as before
    assert kept == tmp_path / "show.1.jsonl" and kept.read_bytes().startswith(before)
