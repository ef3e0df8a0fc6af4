"""Shared by the tests of a take header's keys (a way of stepping recorded so older takes replay as
they were): a take replayed to its end, and a copy of a take with its header edited."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

from puppet.replay import Replayer, build_performance
from puppet.session import read_session


def replay_to_end(take: Path, rig: str | None = None, **ways: Any) -> Replayer:
    """The take replayed through its last tick (on `rig`, as `puppet replay --rig`), with the
    performance's attributes `ways` (e.g. lids_apart=True) set over what its header says."""
    perf = build_performance(read_session(take), None, rig_path=rig)
    for name, value in ways.items():
        if value is not None:
            setattr(perf, name, value)
    rp = Replayer(perf)
    rp.seek(perf.ticks)
    return rp


def with_header(take: Path, out: Path, edit: Callable[[dict[str, Any]], None]) -> Path:
    """A copy of `take` at `out` whose header `edit` changed in place."""
    lines = take.read_text().splitlines()
    header = json.loads(lines[0])
    edit(header)
    out.write_text("\n".join([json.dumps(header)] + lines[1:]) + "\n")
    return out
