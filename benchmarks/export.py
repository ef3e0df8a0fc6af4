"""Export speed: a 720p H.264 MP4 of a recorded performance, as a multiple of real time
(seconds of performance exported per second of wall time; target >= 2x). Also times the data
exports (PC2, channel CSV, ARKit CSV) that need no rendering.

The performance is an 8 s scripted SGI-box take recorded through the real live loop (virtual clock).
Rendering is offscreen (EGL; Mesa's llvmpipe on a machine without a GPU), one render process per core;
H.264 with x264 `ultrafast` at CRF 20 (puppet.export.video defaults).

Run:  .venv/bin/python benchmarks/export.py [--seconds 8] [--fps 30] [--size 1280x720] [--json]
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import devices  # noqa: E402
from puppet import live  # noqa: E402
from puppet.export.runner import ExportOptions, export  # noqa: E402
from puppet.mapping import Mapper  # noqa: E402
from puppet.replay import build_performance  # noqa: E402
from puppet.session import SessionWriter, read_session  # noqa: E402

SCRIPT = """
impersonate = "sgi"
speed = 0
duration = {seconds}
[[sine]]
control = "dial1"
duration = {seconds}
freq = 0.5
amplitude = 0.5
offset = 0.5
rate = 60
[[sine]]
control = "dial7"
duration = {seconds}
freq = 0.7
amplitude = 0.3
offset = 0.3
rate = 60
"""


def record(tmp: Path, seconds: float) -> Path:
    (tmp / "s.toml").write_text(SCRIPT.format(seconds=seconds))
    face = live.load_face()
    dev = devices.open_device(f"mock://{tmp / 's.toml'}")
    spec = live.build_mapping(face.vocab, None, [dev.spec])
    rec = tmp / "take.jsonl"
    w = SessionWriter(rec, live.session_header(face, spec, 60.0, [dev.spec]))
    core = live.LiveCore(face, Mapper(spec, face.vocab), writer=w)
    live.run_virtual(core, live.scripted_events([dev]), seconds)
    w.close(core.tick_count)
    dev.close()
    return rec


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=8.0)
    ap.add_argument("--fps", type=float, default=30.0)
    ap.add_argument("--size", default="1280x720")
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args()
    size = tuple(int(x) for x in a.size.split("x"))
    res: dict[str, dict[str, float]] = {}
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        perf = build_performance(read_session(record(tmp, a.seconds)), None)
        for name, out, opts in [
            (f"mp4 {size[0]}x{size[1]} @{a.fps:g}", tmp / "v.mp4", ExportOptions(fps=a.fps, size=size)),  # type: ignore[arg-type]
            ("pc2 @60", tmp / "f.pc2", ExportOptions(fps=60)),
            ("csv @60", tmp / "c.csv", ExportOptions(fps=60)),
            ("arkit csv @60", tmp / "a.arkit.csv", ExportOptions(fps=60)),
        ]:
            t0 = time.perf_counter()
            export(perf, out, opts)
            wall = time.perf_counter() - t0
            res[name] = {"performance_s": perf.duration, "wall_s": wall, "x_realtime": perf.duration / wall}
    if a.json:
        print(json.dumps(res, indent=2))
    else:
        for name, r in res.items():
            print(f"{name:22s} {r['performance_s']:.1f} s of performance in {r['wall_s']:6.2f} s: "
                  f"{r['x_realtime']:6.2f}x real time")
    return 0


if __name__ == "__main__":
    sys.exit(main())
