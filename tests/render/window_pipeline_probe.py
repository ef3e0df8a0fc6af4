"""Run by test_render_window.py in its own process: a FaceWindow on $DISPLAY drawing a face's onset
serially, then pipelined (render.pipeline), each frame read back by an `after_draw` callback just
before it is shown; writes the pictures per state (serial.npz, pipelined.npz) and the order the
states were shown in (shown.json) to OUT_DIR."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np


def main(out_dir: str) -> int:
    sys.path.insert(0, str(Path(__file__).parent))
    from render_faces import simulate_faces

    from render.window import FaceWindow

    out = Path(out_dir)
    faces = simulate_faces()
    states = faces.frames[::5]
    shown: dict[str, list[int]] = {}
    with FaceWindow(faces.model, size=(320, 240), title="pipeline probe", vsync=False) as win:
        win.show_hud = False  # its fps reading differs between the runs
        for mode in ("serial", "pipelined"):
            win.pipelined = mode == "pipelined"
            pictures: dict[str, np.ndarray] = {}
            order: list[int] = []
            feed = iter(states)

            def next_state(w: FaceWindow, t: float) -> None:
                w.state = next(feed, w.state)

            def read(w: FaceWindow) -> None:
                k = next(i for i, s in enumerate(states) if s is w.drawn)
                pictures.setdefault(f"f{k}", w.read_pixels())

            win.add_frame_callback(next_state)
            win.after_draw.append(read)
            for _ in range(len(states)):
                win.step()
            win.present()  # the last frame drawn (pipelined: not yet shown)
            order = [next(i for i, s in enumerate(states) if s is win.shown)]
            shown[mode] = order
            win._frame_callbacks.remove(next_state)
            win.after_draw.remove(read)
            np.savez(out / f"{mode}.npz", **pictures)
    (out / "shown.json").write_text(json.dumps(shown))
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1]))
