"""What `puppet fit` writes: a take (a session recording, replayed exactly by `puppet replay`),
keyframe curves, and the per-frame report; each to a temporary file beside the target, renamed
into place, so a failure leaves no partial file."""

from __future__ import annotations

import csv
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO, Any

import numpy as np

from puppet.errors import ConfigError


@contextmanager
def atomic_path(target: Path, what: str) -> Iterator[Path]:
    """`safefile.atomic_path` (a temporary file beside `target`, renamed onto it if the block
    succeeds), with a failure to write named as the `what` it was."""
    import safefile

    try:
        with safefile.atomic_path(target) as tmp:
            yield tmp
    except OSError as err:
        raise ConfigError(f"{target}: cannot write the {what}: {err.strerror or err}") from err


def resample(times: np.ndarray, values: np.ndarray, rate: float) -> np.ndarray:
    """(ticks, C) values at ticks k / rate after the first time, linearly interpolated."""
    t = np.asarray(times, float) - float(times[0])
    n = int(np.floor(t[-1] * rate + 1e-9)) + 1
    ticks = np.arange(n) / rate
    return np.stack([np.interp(ticks, t, values[:, j]) for j in range(values.shape[1])], axis=1)


def full_values(face: Any, channels: tuple[str, ...] | list[str], acts: np.ndarray,
                extra: dict[str, float] | None = None) -> np.ndarray:
    """(T, C) channel values in the face's order: defaults, the given channels set (clipped to
    their ranges), and constant `extra` channels (e.g. age)."""
    names = [c.name for c in face.vocab.channels]
    out = np.tile(np.array(face.vocab.defaults(), float), (len(acts), 1))
    lo = np.array([c.lo for c in face.vocab.channels])
    hi = np.array([c.hi for c in face.vocab.channels])
    for j, ch in enumerate(channels):
        if ch in names:
            out[:, names.index(ch)] = acts[:, j]
    for ch, v in (extra or {}).items():
        out[:, names.index(ch)] = v
    return np.clip(out, lo, hi)


def write_take(path: Path, face: Any, values: np.ndarray, rate: float, source: dict[str, Any],
               progress: Callable[[int, int], None] | None = None) -> None:
    """A recording of `values` (ticks, C) at `rate`, with the position digests a live session
    writes (every 60 ticks), computed by simulating it, so `puppet replay` verifies it."""
    import sim
    from puppet.live import CHECK_TICKS, take_header
    from puppet.replay import state_digest
    from puppet.session import SessionWriter

    header = {**take_header(face, rate, {"source": "puppet fit", "text": ""}, []), "source": source}
    simulator = sim.Simulator(face.model, 1.0 / rate)
    control = sim.FaceControl(face.model)
    state = face.model.rest_state()
    with atomic_path(path, "take") as tmp:
        with SessionWriter(tmp, header, clock=lambda: 0.0) as w:
            for k in range(len(values)):
                w.values(k, values[k])
                control.values[...] = values[k]
                simulator.step(state, control)
                if (k + 1) % CHECK_TICKS == 0:
                    w.check(k + 1, state_digest(state))
                w.tick(k + 1)
                if progress and (k % 600 == 0 or k + 1 == len(values)):
                    progress(k + 1, len(values))
            w.close(len(values))
            if w.error is not None:
                raise ConfigError(f"{path}: cannot write the take: {w.error.strerror or w.error}")


def write_curves(path: Path, face: Any, values: np.ndarray, rate: float) -> None:
    from puppet.curves import curves_from_values

    text = curves_from_values(values, [c.name for c in face.vocab.channels], rate, face.vocab)
    with atomic_path(path, "curves") as tmp:
        tmp.write_text(text, encoding="utf-8")


def write_report(path: Path, reports: list[Any]) -> None:
    """One row per input frame: time, residual_mm, misfit, condition, relinearised, scale,
    rotation_degrees, active (channel names joined by '+')."""
    with atomic_path(path, "report") as tmp:
        with open(tmp, "w", newline="", encoding="utf-8") as fh:
            _rows(fh, reports)


def _rows(fh: IO[str], reports: list[Any]) -> None:
    w = csv.writer(fh)
    w.writerow(["time", "residual_mm", "misfit", "condition", "relinearised", "scale", "rotation_degrees", "active"])
    for r in reports:
        w.writerow([f"{r.time:.6f}", f"{r.residual_mm:.4f}", f"{r.misfit:.4f}", f"{r.condition:.4g}",
                    int(r.relinearised), f"{r.scale:.5f}", f"{r.rotation_degrees:.3f}", "+".join(r.active)])
