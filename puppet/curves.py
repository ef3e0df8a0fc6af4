"""Keyframe curves: the seed's "2D graphs of force amplitude over time" as an editable text file.

    facepuppet-curves 1
    # curve TARGET [linear|smooth|step] [replace|add|max]; then "time value" lines, seconds
    curve zygomaticus_major smooth replace
      0.000  0
      0.500  0.8
    end

TARGET is anything a mapping binding accepts: a channel, a `_l/_r` pair as one, an AU (`AU12`) or an
expression (`expr:happiness`); values are in channel units (0..1 weights for AUs and expressions).
A curve acts between its first and last key; outside that span the channel keeps its underlying
value (the recording, or neutral). `replace` sets the value, `add` adds to it, `max` takes the larger.
Curves are evaluated at each tick's time, so playing them is as deterministic as a recording.

Version 2 (what `puppet edit` writes; version 1 files read as before) adds, all optional:
    take TAKE.jsonl SHA1       the take these curves are layered over (file name, first 16 hex digits
                               of its SHA-1), so a tool can say when the take is not the one edited
    0.500  0.8  step           a third word on a key: the interpolation of the segment that starts
                               at this key (default: the curve's)
Several curves may name the same target: they apply in file order, each only between its first and
last key (a re-recorded pass is its own curve, so nothing outside it changes). Limits: at most
MAX_CURVES curves and MAX_KEYS keys in a file."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from puppet.errors import ChannelError, ConfigError
from puppet.mapping.targets import Target, Vocabulary
from safefile import BadFile, atomic_write, quote, read_text

MAGIC = "facepuppet-curves"
INTERPS = ("linear", "smooth", "step")
MODES = ("replace", "add", "max")
SPAN_EPS = 1e-6  # key times are written with 6 decimals
MAX_SECONDS = 24 * 3600.0  # a day: a replay of the curves is allocated per tick
MAX_VALUE = 1e9  # values are clamped to the channel's range; beyond this it is a typo
VERSIONS = ("1", "2")
MAX_CURVES = 5000
MAX_KEYS = 1_000_000


@dataclass
class Curve:
    """One curve: sorted key times (s) and values."""

    target: str
    interp: str
    mode: str
    times: np.ndarray
    values: np.ndarray
    line: int = 0
    #: per key, the interpolation of the segment starting there (version 2); None: `interp` for all
    segs: list[str] | None = None

    def at(self, t: float) -> float | None:
        """Value at time t, or None outside the keyed span."""
        ts, vs = self.times, self.values
        if len(ts) == 0 or t < ts[0] - SPAN_EPS or t > ts[-1] + SPAN_EPS:
            return None
        k = int(np.searchsorted(ts, t, side="right")) - 1
        k = min(max(k, 0), len(ts) - 1)
        interp = self.interp if self.segs is None else self.segs[k]
        if k == len(ts) - 1 or interp == "step":
            return float(vs[k])
        span = ts[k + 1] - ts[k]
        u = 0.0 if span <= 0 else (t - ts[k]) / span
        if interp == "smooth":
            u = u * u * (3.0 - 2.0 * u)
        return float(vs[k] + (vs[k + 1] - vs[k]) * u)


@dataclass
class CurveSet:
    curves: list[Curve]
    source: str = "<curves>"
    version: int = 1
    take: tuple[str, str] | None = None

    @property
    def duration(self) -> float:
        return max((float(c.times[-1]) for c in self.curves if len(c.times)), default=0.0)


def parse_curves(text: str, source: str = "<curves>") -> CurveSet:
    """Parse the text format; errors name file:line."""
    curves: list[Curve] = []
    cur: dict | None = None
    seen_magic = False
    version = 1
    take: tuple[str, str] | None = None
    nkeys = 0

    def fail(lineno: int, msg: str) -> ConfigError:
        return ConfigError(f"{source}:{lineno}: {msg}")

    for lineno, line in enumerate(text.splitlines(), start=1):
        s = line.split("#", 1)[0].strip()
        if not s:
            continue
        parts = s.split()
        if not seen_magic:
            if parts[0] != MAGIC or len(parts) != 2 or parts[1] not in VERSIONS:
                raise fail(lineno, f"expected the first line to be '{MAGIC} 1' or '{MAGIC} 2'")
            seen_magic = True
            version = int(parts[1])
            continue
        if parts[0] == "take" and version >= 2 and cur is None:
            if len(parts) != 3 or not all(c in "0123456789abcdef" for c in parts[2]) or take is not None:
                raise fail(lineno, "expected one 'take FILE SHA1' line (a file name and hex digits)")
            take = (parts[1], parts[2])
            continue
        if parts[0] == "curve":
            if cur is not None:
                raise fail(lineno, "expected 'end' before the next curve")
            if len(parts) < 2 or len(parts) > 4:
                raise fail(lineno, "expected 'curve TARGET [linear|smooth|step] [replace|add|max]'")
            interp, mode = "linear", "replace"
            for word in parts[2:]:
                if word in INTERPS:
                    interp = word
                elif word in MODES:
                    mode = word
                else:
                    raise fail(lineno, f"unknown word {quote(word)}; expected one of {', '.join(INTERPS + MODES)}")
            cur = {"target": parts[1], "interp": interp, "mode": mode, "keys": [], "line": lineno}
        elif parts[0] == "end":
            if cur is None:
                raise fail(lineno, "'end' without a 'curve'")
            keys = cur["keys"]
            if not keys:
                raise fail(lineno, f"curve {quote(cur['target'])} has no keys")
            segs = [k[2] or cur["interp"] for k in keys] if any(k[2] for k in keys) else None
            curves.append(Curve(cur["target"], cur["interp"], cur["mode"], np.array([k[0] for k in keys]),
                                np.array([k[1] for k in keys]), cur["line"], segs))
            if len(curves) > MAX_CURVES:
                raise fail(lineno, f"more than {MAX_CURVES} curves; split the file")
            cur = None
        else:
            if cur is None:
                raise fail(lineno, f"expected 'curve TARGET ...' or a comment, got {quote(s)}")
            seg = None
            if len(parts) == 3 and version >= 2:
                seg = parts[2]
                if seg not in INTERPS:
                    raise fail(lineno, f"unknown segment {quote(seg)}; expected one of {', '.join(INTERPS)}")
            elif len(parts) != 2:
                raise fail(lineno, "expected a key as 'time value' (two numbers)"
                           + (", then optionally linear|smooth|step" if version >= 2 else ""))
            try:
                t, v = float(parts[0]), float(parts[1])
            except ValueError:
                raise fail(lineno, f"expected two numbers 'time value', got {quote(s)}") from None
            if not (np.isfinite(t) and np.isfinite(v)) or not 0 <= t <= MAX_SECONDS or abs(v) > MAX_VALUE:
                raise fail(lineno, f"expected a time in 0..{MAX_SECONDS:g} s and a value within +-{MAX_VALUE:g}")
            if cur["keys"] and t < cur["keys"][-1][0]:
                raise fail(lineno, f"key time {t} goes back in time (keys must be in order)")
            cur["keys"].append((t, v, seg))
            nkeys += 1
            if nkeys > MAX_KEYS:
                raise fail(lineno, f"more than {MAX_KEYS} keys; reduce the keys or split the file")
    if cur is not None:
        raise fail(cur["line"], f"curve {quote(cur['target'])} is not closed with 'end'")
    if not seen_magic:
        raise ConfigError(f"{source}:1: empty curves file; expected '{MAGIC} 1'")
    return CurveSet(curves, source, version, take)


def format_curves(curves: CurveSet, comment: str = "") -> str:
    """The version 2 text of a curve set (times to the microsecond, values to 9 digits)."""
    lines = [f"{MAGIC} 2"]
    if comment:
        lines += [f"# {x}" for x in comment.splitlines()]
    if curves.take is not None:
        lines.append(f"take {curves.take[0]} {curves.take[1]}")
    for c in curves.curves:
        lines.append(f"curve {c.target} {c.interp} {c.mode}")
        for k, (t, v) in enumerate(zip(c.times, c.values)):
            seg = "" if c.segs is None or c.segs[k] == c.interp else f"  {c.segs[k]}"
            lines.append(f"  {float(t):.6f}  {float(v):.9g}{seg}")
        lines.append("end")
    return "\n".join(lines) + "\n"


def save_text(path: str | Path, text: str) -> Path:
    """Write text to a temporary file beside `path` and rename it into place."""
    with atomic_write(path, "w", encoding="utf-8", newline="\n") as fh:
        fh.write(text)
    return Path(path)


def load_curves(path: str | Path) -> CurveSet:
    p = Path(path)
    try:
        text = read_text(p, "curves file", 64 * 1024 * 1024)
    except BadFile as err:
        raise ConfigError(str(err)) from err
    return parse_curves(text, str(p))


class CurveLayer:
    """Curves resolved against a face: `apply(values, t)` overlays them on one tick's values."""

    def __init__(self, curves: CurveSet, vocab: Vocabulary) -> None:
        self.vocab = vocab
        self.lo = np.array([c.lo for c in vocab.channels])
        self.hi = np.array([c.hi for c in vocab.channels])
        self.items: list[tuple[Curve, Target]] = []
        for c in curves.curves:
            try:
                self.items.append((c, vocab.resolve(c.target)))
            except ChannelError as err:
                raise ConfigError(f"{curves.source}:{c.line}: {err}") from err

    def apply(self, values: np.ndarray, t: float) -> np.ndarray:
        out = values.copy()
        for curve, target in self.items:
            v = curve.at(t)
            if v is None:
                continue
            for ch, w in target.channels:
                x = v if target.direct else v * w
                if curve.mode == "replace":
                    out[ch] = x
                elif curve.mode == "add":
                    out[ch] = out[ch] + x
                else:
                    out[ch] = max(out[ch], x)
        np.clip(out, self.lo, self.hi, out=out)
        return out


def _simplify(y: np.ndarray, tol: float) -> list[int]:
    """Ramer-Douglas-Peucker on (index, y): the keys a linear curve needs to stay within tol."""
    n = len(y)
    if n <= 2:
        return list(range(n))
    keep = np.zeros(n, dtype=bool)
    keep[0] = keep[-1] = True
    stack = [(0, n - 1)]
    while stack:
        a, b = stack.pop()
        if b - a < 2:
            continue
        x = np.arange(a + 1, b)
        line = y[a] + (y[b] - y[a]) * (x - a) / (b - a)
        err = np.abs(y[a + 1:b] - line)
        k = int(np.argmax(err))
        if err[k] > tol:
            m = a + 1 + k
            keep[m] = True
            stack += [(a, m), (m, b)]
    return np.flatnonzero(keep).tolist()


def curves_from_values(values: np.ndarray, names: list[str], rate: float, vocab: Vocabulary,
                       tolerance: float = 0.002) -> str:
    """Keyframe curves text for a (ticks, C) array of channel values: only channels that move,
    `_l/_r` pairs that move together as one curve, keys reduced to within `tolerance` of the range."""
    lines = [f"{MAGIC} 1", "# exported by puppet replay; edit and play back with: puppet replay --curves FILE",
             "# curve TARGET [linear|smooth|step] [replace|add|max]; keys are 'seconds value'"]
    done: set[str] = set()
    spans = {c.name: (c.hi - c.lo) or 1.0 for c in vocab.channels}
    for j, name in enumerate(names):
        if name in done:
            continue
        col = values[:, j]
        if len(col) == 0 or np.all(col == col[0]):
            continue
        target = name
        if name.endswith("_l") and name[:-2] + "_r" in names:
            k = names.index(name[:-2] + "_r")
            if np.array_equal(values[:, k], col):
                target = name[:-2]
                done.add(name[:-2] + "_r")
        done.add(name)
        keys = _simplify(col, tolerance * spans.get(name, 1.0))
        lines.append(f"curve {target} linear replace")
        lines += [f"  {k / rate:.6f}  {col[k]:.6g}" for k in keys]
        lines.append("end")
    return "\n".join(lines) + "\n"
