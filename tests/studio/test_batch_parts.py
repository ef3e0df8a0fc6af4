"""What a batch removes from its output folder when it ends: the half-written files its killed
workers left, never a file another run is writing there now."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

from puppet.batch.run import _remove_parts
from safefile import atomic_write, part_in_use


def test_a_batch_removes_what_dead_writers_left_and_keeps_what_a_live_one_writes(tmp_path: Path) -> None:
    """Two batches into one folder (or a batch and `puppet replay --out` there): the first to end
    removed the other's temporary file mid-write, and that export failed ("cannot write: No such
    file or directory")."""
    dead = tmp_path / ".take.k1lled00.part.csv"
    with atomic_write(tmp_path / "take.csv") as fh:
        fh.write("written by another run\n")
        live = [p for p in tmp_path.iterdir() if ".part" in p.name]
        dead.write_text("left by a worker that was killed\n")
        assert len(live) == 1 and part_in_use(live[0]) and not part_in_use(dead)
        _remove_parts(tmp_path, [SimpleNamespace(name="take.csv")])  # type: ignore[list-item]
        assert live[0].exists() and not dead.exists()
    assert (tmp_path / "take.csv").read_text() == "written by another run\n"
    assert [p.name for p in tmp_path.iterdir()] == ["take.csv"]
