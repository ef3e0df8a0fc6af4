"""`puppet recognize`: the expression a take or a capture shows, per time span."""

from __future__ import annotations

import argparse
import json
from pathlib import Path


def register(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = subparsers.add_parser(
        "recognize",
        help="which expression a take or capture shows, per time span (scores for every preset and neutral)",
        description="Matches each frame's skin displacement against templates of the presets' displacement "
        "fields built by the simulator (seed 000 section 6), and the fitted activations against the "
        "presets' channels; prints the spans with scores for each preset and neutral, from both. TAKE: a "
        "recording (.jsonl), re-simulated; INPUT: anything `puppet fit` reads (fitted first). --json prints "
        'a list of {"start": s, "end": s, "expression": name, "scores": {name: score}}: the templates\' '
        "verdict, or the activations' with --by activations. See docs/fit.md.",
    )
    p.add_argument("input", metavar="TAKE|INPUT", help="a take (.jsonl) or a capture")
    p.add_argument("--rig", metavar="R", help="rig file (default: the take's rig or the built-in face)")
    p.add_argument("--face", metavar="SPEC", help="the face, if not the take's (as puppet fit and replay): ict, "
                   "ict?identity=SEED, procedural or a saved identity's NAME")
    p.add_argument("--map", metavar="CORR.json", help="correspondence file for other point layouts")
    p.add_argument("--fps", type=float, metavar="N", help="frame rate of PC2 samples / ARKit timecodes")
    p.add_argument("--json", action="store_true", help="machine-readable spans")
    p.add_argument("--by", choices=("templates", "activations"), default="templates",
                   help="whose verdict --json lists: the displacement templates' (default) or the fitted "
                   "activations' (the text output shows both)")
    p.set_defaults(func=run)


def _take_motion(path: str, rig: str | None, face: str | None = None) -> tuple[object, object, object, object]:
    """(face, times, displacement of every vertex (T, N, 3), activations (T, K)) of a take."""
    import sys

    from puppet.replay import build_performance
    from puppet.session import read_session

    session = read_session(path)
    for w in session.warnings:
        print(f"puppet: warning: {w}", file=sys.stderr)
    if session.ticks < 1:
        from puppet.errors import ConfigError

        raise ConfigError(f"{path}: the take has no ticks")
    perf = build_performance(session, None, rig, face=face)
    return perf.face, perf.values, perf.rate, [c.name for c in perf.face.vocab.channels]


def analyse(args: argparse.Namespace) -> tuple[list, list]:
    """(spans from the templates, the same spans from the activations)."""
    import numpy as np

    from puppet.capture import ChannelCapture, read_capture
    from puppet.capture.fitting import face_basis, fit_points, simulate_take
    from puppet.capture.take import full_values, resample
    from puppet.live import load_face
    from sim.fit.recognize import activation_scores, segment, span_scores, template_scores

    p = Path(args.input)
    if p.suffix.lower() == ".jsonl":
        face, values, rate, names = _take_motion(args.input, args.rig, getattr(args, "face", None))
    else:
        face = load_face(args.rig, face=getattr(args, "face", None))
        cap = read_capture(p, face, args.map, args.fps)
        values = None
        if isinstance(cap, ChannelCapture):
            rate = 60.0
            values = resample(cap.times, full_values(face, cap.channels, cap.values), rate)
            names = [c.name for c in face.vocab.channels]
    settler, basis, tpl = face_basis(face)
    if values is not None:
        # about 30 frames a second; a take shorter than one such frame (a tick or two) is read at
        # its own rate: none was simulated and the arrays did not match (a ValueError traceback)
        every = max(1, min(int(round(rate / 30.0)), len(values)))
        times, pos = simulate_take(face, values, rate, every)
        disp = pos - basis.rest[None]
        verts = np.arange(face.model.n_vertices)
        idx = [names.index(c) for c in basis.channels]
        acts = values[every - 1::every][: len(times), idx]
    else:
        result = fit_points(cap, settler, basis)
        times, disp, verts, acts = result.times, result.displacements, result.vertices, result.activations
    spans = segment(times, template_scores(disp, tpl, verts), tpl.names)
    by_acts = span_scores(times, activation_scores(acts, tpl), tpl.names, spans)
    return spans, by_acts


def _top(scores: dict[str, float], n: int = 3) -> str:
    best = sorted(scores.items(), key=lambda kv: -kv[1])[:n]
    return ", ".join(f"{k} {v:.2f}" for k, v in best)


def run(args: argparse.Namespace) -> int:
    spans, by_acts = analyse(args)
    if args.json:
        chosen = by_acts if args.by == "activations" else spans
        out = [{"start": round(s.start, 4), "end": round(s.end, 4), "expression": v.expression, "scores": v.scores}
               for s, v in zip(spans, chosen)]
        print(json.dumps(out))
        return 0
    print("      start       end  templates                              activations")
    for s, a in zip(spans, by_acts):
        print(f"{s.start:9.2f} s {s.end:7.2f} s  {s.expression:<10} ({_top(s.scores, 2):<24})  "
              f"{a.expression:<10} ({_top(a.scores, 2)})")
    return 0
