"""The live window (glfw): the one place besides `render.offscreen` that creates an OpenGL context.
It shows a face with the same FaceRenderer as the offscreen path, lets the viewer orbit, zoom and
switch views, and hands every key and every frame to the live loop through callbacks; it knows
nothing about devices or the simulation beyond the state it is given."""

from __future__ import annotations

import os
import sys
import time
import warnings
from collections.abc import Callable
from dataclasses import replace
from typing import Any

import glfw
import moderngl
import numpy as np

from render.hud import HudInfo
from render.pipeline import find_rasterizer, flush
from render.renderer import VIEWS, FaceRenderer, affordable_antialias

KeyCallback = Callable[[str, str, float], None]
FrameCallback = Callable[["FaceWindow", float], None]

#: help for the window's own keys (`builtin_keys`); an owner that turns them off passes its own
HELP_LINES = [
    "drag: orbit   scroll: zoom   R / Home: reset view",
    "1-5: shaded, wireframe, muscles, trails, heat   V: next view",
    "F11: fullscreen   F2: antialiasing   H: HUD   F1 / ?: this help   Esc: quit",
]
MOUSE_HELP = ["drag: orbit   scroll: zoom"]
_ACTIONS = {glfw.PRESS: "press", glfw.RELEASE: "release", glfw.REPEAT: "repeat"}
_SPECIAL = {
    glfw.KEY_SPACE: "space", glfw.KEY_ESCAPE: "escape", glfw.KEY_ENTER: "enter", glfw.KEY_TAB: "tab",
    glfw.KEY_BACKSPACE: "backspace", glfw.KEY_LEFT: "left", glfw.KEY_RIGHT: "right",
    glfw.KEY_UP: "up", glfw.KEY_DOWN: "down", glfw.KEY_HOME: "home", glfw.KEY_END: "end",
    glfw.KEY_PAGE_UP: "page_up", glfw.KEY_PAGE_DOWN: "page_down", glfw.KEY_INSERT: "insert",
    glfw.KEY_DELETE: "delete", glfw.KEY_LEFT_SHIFT: "shift", glfw.KEY_RIGHT_SHIFT: "shift",
    glfw.KEY_LEFT_CONTROL: "ctrl", glfw.KEY_RIGHT_CONTROL: "ctrl", glfw.KEY_LEFT_ALT: "alt",
    glfw.KEY_RIGHT_ALT: "alt", **{getattr(glfw, f"KEY_F{i}"): f"f{i}" for i in range(1, 13)},
}
ORBIT_RAD_PER_PX = 0.008


class NoDisplayError(RuntimeError):
    """No window can be opened here (no DISPLAY, or glfw cannot reach it)."""


def key_name(key: int, scancode: int) -> str:
    """A stable lower-case name: the printed character ("a", "1", "/") or a name ("left", "f11")."""
    if key in _SPECIAL:
        return _SPECIAL[key]
    name = glfw.get_key_name(key, scancode)
    return name.lower() if name else f"key{key}"


class FaceWindow:
    """A resizable window showing `state` (set it each frame) with an optional `hud` (HudInfo).

    Hooks for the live loop: `add_key_callback(fn(name, action, t))` receives every key press,
    release and repeat (t = time.monotonic()); `add_frame_callback(fn(window, t))` runs before each
    frame is drawn, where the loop steps the face and sets `window.state` / `window.hud`.

    Keys: with `builtin_keys` (the default) the window answers its own keys (HELP_LINES). An owner
    with its own keys sets `builtin_keys = False` and gives `key_help`, the lines the help shows
    (toggled by `show_help`; `?` toggles it too whenever there is help to show), so the help always
    lists the keys that are actually active."""

    def __init__(self, model: Any, size: tuple[int, int] = (1280, 720), title: str = "facepuppet",
                 view: str = "shaded", visible: bool = True, vsync: bool = True,
                 antialias: str | None = None, builtin_keys: bool = True,
                 key_help: list[str] | None = None) -> None:
        if not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
            raise NoDisplayError("no display: DISPLAY is not set")
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            if not glfw.init():
                raise NoDisplayError(f"no display: glfw cannot start ({_glfw_error()})")
        glfw.window_hint(glfw.CONTEXT_VERSION_MAJOR, 3)
        glfw.window_hint(glfw.CONTEXT_VERSION_MINOR, 3)
        glfw.window_hint(glfw.OPENGL_PROFILE, glfw.OPENGL_CORE_PROFILE)
        if sys.platform == "darwin":  # macOS needs it; elsewhere it would forbid wide lines
            glfw.window_hint(glfw.OPENGL_FORWARD_COMPAT, True)
        glfw.window_hint(glfw.DEPTH_BITS, 24)
        glfw.window_hint(glfw.VISIBLE, visible)
        glfw.window_hint(glfw.RESIZABLE, True)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            self.win = glfw.create_window(int(size[0]), int(size[1]), title, None, None)
        if not self.win:
            msg = _glfw_error()
            glfw.terminate()
            raise NoDisplayError(f"no display: cannot open an OpenGL 3.3 window ({msg})")
        glfw.make_context_current(self.win)
        glfw.swap_interval(1 if vsync else 0)
        self.ctx = moderngl.create_context(require=330)
        find_rasterizer()  # llvmpipe's threads, for render.pipeline.steer_rasterizer
        self.renderer = FaceRenderer(self.ctx, view=view,
                                     antialias=antialias or affordable_antialias(self.ctx))
        self.renderer.populate(model)
        self.model = model
        self.state: Any = model.rest_state()
        self.hud: HudInfo | None = None
        self.show_hud = True
        self.show_help = False
        self.builtin_keys = builtin_keys
        self.key_help: list[str] | None = None if key_help is None else list(key_help)
        self.fps = 0.0
        #: pipelined frames (render.pipeline): each step makes its frame's CPU half while llvmpipe
        #: still rasterises the frame the step before drew, then shows that frame and draws its own;
        #: a frame is shown one step later than serially (`shown` says which state is on screen)
        self.pipelined = False
        #: the state whose frame is in the back buffer, drawn and not yet shown (what `after_draw`
        #: callbacks read back), and the state of the frame last shown (swapped)
        self.drawn: Any = None
        self.shown: Any = None
        self.frames_shown = 0  # swaps so far
        self._last_frame: float | None = None
        self._drag: tuple[float, float] | None = None
        self._windowed: tuple[int, int, int, int] | None = None
        self._key_callbacks: list[KeyCallback] = []
        self._frame_callbacks: list[FrameCallback] = []
        #: called with the window after each frame is drawn and before it is shown (read_pixels works)
        self.after_draw: list[Callable[[FaceWindow], None]] = []
        glfw.set_key_callback(self.win, self._on_key)
        glfw.set_char_callback(self.win, self._on_char)
        glfw.set_mouse_button_callback(self.win, self._on_mouse_button)
        glfw.set_cursor_pos_callback(self.win, self._on_cursor)
        glfw.set_scroll_callback(self.win, self._on_scroll)

    # -- hooks ----------------------------------------------------------------------------------
    def add_key_callback(self, fn: KeyCallback) -> None:
        self._key_callbacks.append(fn)

    def add_frame_callback(self, fn: FrameCallback) -> None:
        self._frame_callbacks.append(fn)

    # -- loop -----------------------------------------------------------------------------------
    @property
    def should_close(self) -> bool:
        return bool(glfw.window_should_close(self.win))

    def request_close(self) -> None:
        glfw.set_window_should_close(self.win, True)

    def framebuffer_size(self) -> tuple[int, int]:
        w, h = glfw.get_framebuffer_size(self.win)
        return int(w), int(h)

    def draw(self, prepared: Any = None) -> None:
        """Draw the current state and HUD into the back buffer (without swapping); `prepared`: its
        CPU half made beforehand (FaceRenderer.prepare)."""
        glfw.make_context_current(self.win)
        screen = self.ctx.screen
        screen.use()
        w, h = self.framebuffer_size()
        screen.viewport = (0, 0, max(w, 1), max(h, 1))
        self.renderer.draw(self.state, hud=self._hud_for_frame(), prepared=prepared)

    def step(self, wait: float | None = None) -> bool:
        """One frame: events, frame callbacks, draw, swap. False once the window should close.
        `pipelined`: events, frame callbacks, this frame's CPU half, swap (the frame the step
        before drew), draw and flush this one (shown by the next step).

        wait: block up to this many seconds for an event first (a still face needs no redraws
        until the viewer does something); None polls, for a live face changing every frame."""
        if wait is None:
            glfw.poll_events()
        else:
            glfw.wait_events_timeout(wait)
        now = time.monotonic()
        if self._last_frame is not None:
            dt = max(now - self._last_frame, 1e-6)
            self.fps = 1.0 / dt if self.fps == 0 else 0.9 * self.fps + 0.1 / dt
        self._last_frame = now
        for fn in self._frame_callbacks:
            fn(self, now)
        if self.should_close:
            return False
        if self.pipelined:
            glfw.make_context_current(self.win)
            w, h = self.framebuffer_size()
            prepared = self.renderer.prepare(self.state, (max(w, 1), max(h, 1)))  # the last frame rasterises
            self.present()
            self.draw(prepared)
            flush()
            self.drawn = self.state
            return not self.should_close
        self.draw()
        self.drawn = self.state
        self.present()
        return not self.should_close

    def present(self) -> None:
        """Show the frame drawn and not yet shown, if any (its `after_draw` callbacks first)."""
        if self.drawn is None:
            return
        for fn in self.after_draw:
            fn(self)
        glfw.swap_buffers(self.win)
        self.shown, self.drawn = self.drawn, None
        self.frames_shown += 1

    def run(self, max_frames: int | None = None, wait: float | None = None) -> None:
        """Show frames until the window is closed (or `max_frames` were shown); see `step`."""
        n = 0
        while self.step(wait):
            n += 1
            if max_frames is not None and n >= max_frames:
                break

    def read_pixels(self) -> np.ndarray:
        """(H, W, 3) uint8 of the back buffer as last drawn, top row first (call after draw())."""
        w, h = self.framebuffer_size()
        raw = self.ctx.screen.read(viewport=(0, 0, w, h), components=3, alignment=1)
        return np.frombuffer(raw, np.uint8).reshape(h, w, 3)[::-1].copy()

    def close(self) -> None:
        if self.win is None:
            return
        glfw.make_context_current(self.win)
        self.renderer.release()
        glfw.destroy_window(self.win)
        self.win = None
        glfw.terminate()

    def __enter__(self) -> "FaceWindow":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- HUD ------------------------------------------------------------------------------------
    def _hud_for_frame(self) -> HudInfo | None:
        if not self.show_hud:
            return None
        hud = self.hud if self.hud is not None else HudInfo(lines=["? for keys"])
        if hud.fps is None and self.fps > 0:
            hud = replace(hud, fps=self.fps)
        if self.show_help:
            hud = replace(hud, lines=[*hud.lines, *self.help_lines])
        return hud

    @property
    def help_lines(self) -> list[str]:
        """What the help shows: the owner's key help, else the window's own keys when they are on."""
        if self.key_help is not None:
            return list(self.key_help)
        return list(HELP_LINES if self.builtin_keys else MOUSE_HELP)

    # -- input ----------------------------------------------------------------------------------
    def _on_key(self, win: Any, key: int, scancode: int, action: int, mods: int) -> None:
        name = key_name(key, scancode)
        t = time.monotonic()
        for fn in self._key_callbacks:
            fn(name, _ACTIONS.get(action, "press"), t)
        if self.builtin_keys and action == glfw.PRESS:
            self._builtin(name)

    def _builtin(self, name: str) -> None:
        r = self.renderer
        if name in ("1", "2", "3", "4", "5"):
            r.view = VIEWS[int(name) - 1]
        elif name == "v":
            r.view = VIEWS[(VIEWS.index(r.view) + 1) % len(VIEWS)]
        elif name in ("r", "home"):
            r.camera.reset()
        elif name == "f11":
            self.toggle_fullscreen()
        elif name == "f2":
            r.antialias = "none" if r.antialias == "fxaa" else "fxaa"
        elif name == "h":
            self.show_hud = not self.show_hud
        elif name == "f1":
            self.show_help = not self.show_help
        elif name == "escape":
            self.request_close()

    def _on_char(self, win: Any, codepoint: int) -> None:
        if chr(codepoint) == "?" and (self.builtin_keys or self.key_help is not None):
            self.show_help = not self.show_help

    def _on_mouse_button(self, win: Any, button: int, action: int, mods: int) -> None:
        if button == glfw.MOUSE_BUTTON_LEFT:
            self._drag = glfw.get_cursor_pos(win) if action == glfw.PRESS else None

    def _on_cursor(self, win: Any, x: float, y: float) -> None:
        if self._drag is not None:
            dx, dy = x - self._drag[0], y - self._drag[1]
            self.renderer.camera.orbit(-dx * ORBIT_RAD_PER_PX, dy * ORBIT_RAD_PER_PX)
            self._drag = (x, y)

    def _on_scroll(self, win: Any, dx: float, dy: float) -> None:
        self.renderer.camera.zoom(dy)

    def toggle_fullscreen(self) -> None:
        monitor = glfw.get_primary_monitor()
        if self._windowed is None and monitor:
            x, y = glfw.get_window_pos(self.win)
            w, h = glfw.get_window_size(self.win)
            self._windowed = (x, y, w, h)
            mode = glfw.get_video_mode(monitor)
            glfw.set_window_monitor(self.win, monitor, 0, 0, mode.size.width, mode.size.height,
                                    mode.refresh_rate)
        elif self._windowed is not None:
            x, y, w, h = self._windowed
            self._windowed = None
            glfw.set_window_monitor(self.win, None, x, y, w, h, 0)


def _glfw_error() -> str:
    try:
        code, desc = glfw.get_error()
    except Exception:  # noqa: BLE001 - older pyGLFW without get_error
        return "unknown glfw error"
    return desc.decode() if isinstance(desc, bytes) else str(desc or f"code {code}")
