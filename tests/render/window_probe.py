"""Run by test_render_window.py in its own process (its own GL context, its own glfw): opens a real
FaceWindow on $DISPLAY, screenshots the default framebuffer, types keys at it with xdotool, and
writes what happened to OUT_DIR (screenshot.npy, events.json)."""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import glfw
import numpy as np


def main(out_dir: str) -> int:
    from render.window import FaceWindow
    from sim.face import default_model

    out = Path(out_dir)
    model = default_model(0)
    keys: list[tuple[str, str]] = []
    frames: list[float] = []
    with FaceWindow(model, size=(320, 240), title="probe", vsync=False) as win:
        win.show_hud = False
        win.add_key_callback(lambda name, action, t: keys.append((name, action)))
        win.add_frame_callback(lambda w, t: frames.append(t))
        drawn: list[np.ndarray] = []
        win.after_draw.append(lambda w: drawn.append(w.read_pixels()) if not drawn else None)
        win.step()
        np.save(out / "after_draw.npy", drawn[0])  # what a page's picture is made of
        win.draw()
        np.save(out / "screenshot.npy", win.read_pixels())
        wid = str(glfw.get_x11_window(win.win))
        views = []
        for key in ("2", "3", "v", "r"):
            subprocess.run(["xdotool", "key", "--window", wid, key], check=True)
            deadline = time.monotonic() + 60.0  # a hang guard: the key's arrival is the event
            while time.monotonic() < deadline and not any(k == (key, "press") for k in keys):
                win.step()
                time.sleep(0.01)
            views.append(win.renderer.view)
        win.renderer.camera.orbit(0.5, 0.2)
        subprocess.run(["xdotool", "key", "--window", wid, "Home"], check=True)
        # until the key has come (20 frames stood in for it), as for the keys above
        deadline = time.monotonic() + 60.0
        while time.monotonic() < deadline and not any(k == ("home", "press") for k in keys):
            win.step()
            time.sleep(0.01)
        win.step()
        reset = win.renderer.camera.yaw == 0.0
        size = win.framebuffer_size()
        renderer = win.ctx.info["GL_RENDERER"]
        antialias = win.renderer.antialias
    events = {"keys": keys, "views": views, "frames": len(frames), "reset": reset, "size": size,
              "renderer": renderer, "antialias": antialias}
    (out / "events.json").write_text(json.dumps(events))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1]))
