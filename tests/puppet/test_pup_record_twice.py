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


def test_a_take_named_near_the_file_system_limit_is_kept_aside(tmp_path: Path) -> None:
    """A second show recording to a 254-byte take name: keeping the first take aside as
    NAME.1.jsonl (2 bytes longer) ended the show's start in an OSError traceback ('File name too
    long'). The earlier take is kept under a name cut to fit, its bytes intact, every time."""
    path = tmp_path / ("ö" * 122 + "abcd.jsonl")
    assert len(path.name.encode()) == 254
    for k in range(3):
        path.write_text(f"take {k}\\n")
        kept = keep_previous(path)
        assert kept is not None and kept.read_text() == f"take {k}\\n" and not path.exists()
        assert kept.name.endswith(f".{k + 1}.jsonl") and len(kept.name.encode()) <= 255
    assert len(list(tmp_path.iterdir())) == 3
