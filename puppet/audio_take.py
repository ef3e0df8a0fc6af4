"""The sound of a take: audio inputs record a WAV beside the take (`take.jsonl` -> `take.wav`), its
sample 0 at tick 0 and every sample on the take's tick clock (tick k at k / tick rate seconds), and
the take's header names it: ``"audio": [{"device", "file", "rate"}]``. Replay and export find the
sound through `take_audio`."""

from __future__ import annotations

import sys
import time
from pathlib import Path
from typing import Any


def attach(devs: list[Any], record: str | None, header: dict[str, Any]) -> list[tuple[Any, Any]]:
    """Start a WAV for every audio input of the show; names them in `header`."""
    if not record:
        return []
    from puppet.session import keep_previous

    out = []
    for i, dev in enumerate(d for d in devs if hasattr(d, "record_to")):
        path = Path(record).with_suffix(".wav" if i == 0 else f".{i + 1}.wav")
        kept = keep_previous(path)
        if kept is not None:
            print(f"puppet: {path} already held a recording: kept as {kept}", file=sys.stderr)
        out.append((dev, dev.record_to(str(path))))
    if out:
        header["audio"] = [{"device": d.spec, "file": r.path.name, "rate": r.rate} for d, r in out]
    return out


def clock_hook(recs: list[tuple[Any, Any]]) -> Any:
    """A LiveCore.before_tick hook telling each recorder where the take's clock is: the show's
    schedule (`LiveCore.clock_origin`) when the loop keeps one, so wall time the loop drops is
    dropped from the sound at that very tick; else when each tick ran."""
    def hook(core: Any) -> None:
        origin = core.clock_origin
        if origin is not None:
            for _, rec in recs:
                rec.anchor(origin)
            return
        t = time.monotonic()
        pos = core.tick_count / core.rate
        for _, rec in recs:
            rec.clock(pos, t)

    return hook


def finish(recs: list[tuple[Any, Any]], seconds: float | None = None) -> None:
    """Close every WAV (moved into place), each as long as the take (`seconds`), and say where the
    sound went. The readers get a moment to hand over the blocks captured before the last tick."""
    if recs:
        time.sleep(0.1)
    for dev, rec in recs:
        path = dev.stop_recording(seconds)
        if path is None:
            err = rec.writer.error
            print(f"puppet: warning: the sound of {dev.spec} could not be written"
                  f"{f' ({err.strerror})' if err is not None else ''}; the take is intact", file=sys.stderr)
        else:
            print(f"puppet: sound of {dev.spec} recorded to {path}")


def take_audio(session: Any) -> Path | None:
    """The take's first WAV, if its header names one and it is there."""
    entries = session.header.get("audio")
    if not isinstance(entries, list) or not entries or not isinstance(entries[0], dict):
        return None
    name = entries[0].get("file")
    if not isinstance(name, str) or "/" in name or "\\" in name or not name.lower().endswith(".wav"):
        return None
    own = Path(session.path)
    recorded = name[: -len(".wav")]
    if "path" not in entries[0] and own.stem != recorded and own.stem.startswith(recorded + "."):
        # a take kept aside (`take.jsonl` -> `take.1.jsonl`) took its sound with it (`take.1.wav`);
        # the `take.wav` its header names is the newer take's now
        moved = own.with_suffix(".wav")
        if moved.is_file():
            return moved
    path = own.parent / name
    if path.is_file():
        return path
    elsewhere = entries[0].get("path")  # `puppet fit speech.wav` names the WAV where it is
    if isinstance(elsewhere, str) and elsewhere.lower().endswith(".wav") and Path(elsewhere).is_file():
        return Path(elsewhere)
    return None
