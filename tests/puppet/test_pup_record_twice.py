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


def test_a_kept_take_keeps_its_sound_and_pictures(tmp_path: Path) -> None:
    """What a show wrote beside its take (`take.wav`, the last frame `take.png`, the demo's
    `take.mp4`) goes aside with the take, under one number: the new show's files of those names
    replaced them (a kept take then replayed with the new take's sound). A file already holding
    that number (`take.1.wav`) moves them all to the next."""
    path = tmp_path / "take.jsonl"
    w = SessionWriter(path, {"channels": ["jaw"]}, fsync_seconds=None)
    w.values(0, [0.25])
    w.tick(1)
    w.close(1)
    for suffix in (".wav", ".png", ".mp4"):
        path.with_suffix(suffix).write_bytes(b"the first show's " + suffix.encode())
    (tmp_path / "take.1.wav").write_bytes(b"somebody else's")
    (tmp_path / "other.png").write_bytes(b"not the take's")
    kept = keep_previous(path, companions=True)
    assert kept == tmp_path / "take.2.jsonl"
    for suffix in (".wav", ".png", ".mp4"):
        assert (tmp_path / f"take.2{suffix}").read_bytes() == b"the first show's " + suffix.encode()
        assert not path.with_suffix(suffix).exists()
    assert (tmp_path / "take.1.wav").read_bytes() == b"somebody else's"
    assert (tmp_path / "other.png").exists()
