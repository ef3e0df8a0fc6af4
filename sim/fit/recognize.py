"""Expression recognition, the two ways of Essa & Pentland (1997) on our face:

- **Displacement templates** (seed 000 section 6's "templates of optical flow"): each frame's
  aligned displacement d is compared with each preset's settled displacement field F at the same
  points (`sim.fit.basis.Templates`, at a low and a full weight, since the skin does not scale
  linearly). Shape match c_e = max over weights of cos(d, F), clipped at 0; intensity
  w_e = d.F_1 / |F_1|^2 (the weight the full template would need).
- **Activations**: the fitted activations against each preset's channel vector, the same two
  numbers.

Neutral scores 1 - c_e w_e / w0 (clipped to 0..1) for the best match e, w0 = NEUTRAL_LEVEL: no
motion that looks like an expression, or too little of it. The intensity is a projection, so point
noise leaves it unbiased while it lowers the cosine; weighting by c_e once (not squared) keeps weak
expressions under noise from reading as neutral. Each preset scores c_e (1 - neutral).
Scores are smoothed over a short window before the per-frame winner is taken, and runs of one
winner shorter than `min_span` seconds are merged into the span before them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sim.fit.basis import Templates

NEUTRAL = "neutral"
NEUTRAL_LEVEL = 0.2
WINDOW_SECONDS = 0.1
MIN_SPAN_SECONDS = 0.2


@dataclass
class Span:
    start: float
    end: float
    expression: str
    scores: dict[str, float]


def _scores(match: np.ndarray, intensity: np.ndarray, level: float) -> np.ndarray:
    """(T, E) shape match and intensity -> (T, E + 1) scores, neutral last."""
    c = np.clip(match, 0.0, 1.0)
    best = np.argmax(c, axis=1)
    rows = np.arange(len(c))
    w = c[rows, best] * np.maximum(intensity[rows, best], 0.0)
    neutral = np.clip(1.0 - w / level, 0.0, 1.0)
    return np.concatenate([c * (1.0 - neutral)[:, None], neutral[:, None]], axis=1)


def _cosine(x: np.ndarray, t: np.ndarray) -> np.ndarray:
    """x (T, D), t (E, D) -> (T, E) cosines (0 where either is zero)."""
    nx = np.linalg.norm(x, axis=1)[:, None]
    nt = np.linalg.norm(t, axis=1)[None, :]
    den = nx * nt
    return np.divide(x @ t.T, den, out=np.zeros((len(x), len(t))), where=den > 0)


def template_scores(disp: np.ndarray, templates: Templates, vertices: np.ndarray,
                    level: float = NEUTRAL_LEVEL) -> np.ndarray:
    """(T, E + 1) scores of each frame's displacement (T, P, 3) against the templates."""
    x = disp.reshape(len(disp), -1)
    f = templates.fields[:, :, vertices, :].reshape(len(templates.names), len(templates.weights), -1)
    match = np.max(np.stack([_cosine(x, f[:, w]) for w in range(f.shape[1])]), axis=0)
    full = f[:, -1]
    inten = (x @ full.T) / np.maximum(np.sum(full * full, axis=1), 1e-12)[None, :]
    return _scores(match, inten / templates.weights[-1], level)


def activation_scores(acts: np.ndarray, templates: Templates, level: float = NEUTRAL_LEVEL) -> np.ndarray:
    """(T, E + 1) scores of fitted activations (T, K) against the presets' channel vectors."""
    e = templates.activations
    match = _cosine(acts, e)
    inten = (acts @ e.T) / np.maximum(np.sum(e * e, axis=1), 1e-12)[None, :]
    return _scores(match, inten, level)


def _smooth(scores: np.ndarray, frames: int) -> np.ndarray:
    if frames <= 1 or len(scores) < 2:
        return scores
    k = np.ones(frames) / frames
    pad = frames // 2
    padded = np.pad(scores, ((pad, frames - 1 - pad), (0, 0)), mode="edge")
    return np.stack([np.convolve(padded[:, j], k, mode="valid") for j in range(scores.shape[1])], axis=1)


def _rate(times: np.ndarray) -> float:
    return float(1.0 / np.median(np.diff(times))) if len(times) > 1 else 60.0


def segment(times: np.ndarray, scores: np.ndarray, names: tuple[str, ...],
            min_span: float = MIN_SPAN_SECONDS, window: float = WINDOW_SECONDS) -> list[Span]:
    """Time spans of one winning label each, with the mean scores over the span."""
    labels = (*names, NEUTRAL)
    rate = _rate(times)
    sm = _smooth(scores, max(1, int(round(window * rate))))
    win = np.argmax(sm, axis=1)
    runs: list[list[int]] = []  # [label, first, last]
    for t, w in enumerate(win):
        if runs and runs[-1][0] == w:
            runs[-1][2] = t
        else:
            runs.append([int(w), t, t])
    min_frames = max(1, int(round(min_span * rate)))
    merged: list[list[int]] = []
    for r in runs:
        if merged and (r[2] - r[1] + 1 < min_frames or merged[-1][0] == r[0]):
            merged[-1][2] = r[2]
        else:
            merged.append(r)
    if len(merged) > 1 and merged[0][2] - merged[0][1] + 1 < min_frames:
        merged[1][1] = merged[0][1]
        merged.pop(0)
    spans = []
    for i, (_, a, b) in enumerate(merged):
        mean = sm[a:b + 1].mean(axis=0)
        label = labels[int(np.argmax(mean))]
        end = float(times[merged[i + 1][1]]) if i + 1 < len(merged) else float(times[b])
        spans.append(Span(float(times[a]), end, label, {n: round(float(s), 4) for n, s in zip(labels, mean)}))
    return spans


def span_scores(times: np.ndarray, scores: np.ndarray, names: tuple[str, ...], spans: list[Span],
                window: float = WINDOW_SECONDS) -> list[Span]:
    """The same spans scored by another route (e.g. the activations): mean scores over each."""
    labels = (*names, NEUTRAL)
    sm = _smooth(scores, max(1, int(round(window * _rate(times)))))
    out = []
    for i, sp in enumerate(spans):
        last = spans[i + 1].start if i + 1 < len(spans) else np.inf
        sel = (times >= sp.start) & ((times < last) if i + 1 < len(spans) else (times <= sp.end))
        mean = sm[sel].mean(axis=0) if sel.any() else sm[np.argmin(np.abs(times - sp.start))]
        out.append(Span(sp.start, sp.end, labels[int(np.argmax(mean))],
                        {n: round(float(s), 4) for n, s in zip(labels, mean)}))
    return out
