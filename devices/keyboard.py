"""``keyboard://`` — the fallback control box: keys of the application's own window.

The window lives in ``render/`` and knows nothing of devices; it passes key callbacks here through
``feed_key`` (or the ``glfw_key_callback`` adapter). This module never creates a window; glfw is
imported lazily only to translate key codes to names.
"""

from __future__ import annotations

import string
import threading
import time
from collections.abc import Callable, Iterable
from functools import lru_cache
from typing import Any, Literal

from devices.base import ControlInfo, Device
from devices.errors import DeviceSpecError
from devices.events import ControlEvent
from devices.spec import DeviceSpec

KeyAction = Literal["press", "release", "repeat"]

_NAMED = (
    [*string.ascii_uppercase, *string.digits]
    + [f"F{i}" for i in range(1, 13)]
    + ["SPACE", "ENTER", "TAB", "BACKSPACE", "ESCAPE", "LEFT", "RIGHT", "UP", "DOWN"]
    + ["HOME", "END", "PAGE_UP", "PAGE_DOWN", "INSERT", "DELETE", "SHIFT", "CTRL", "ALT"]
    + [f"KP_{i}" for i in range(10)]
)


#: Left and right modifiers are one control, named as render/window.py names them (upper-cased).
_MODIFIERS = {"LEFT_SHIFT": "SHIFT", "RIGHT_SHIFT": "SHIFT", "LEFT_CONTROL": "CTRL", "RIGHT_CONTROL": "CTRL",
              "LEFT_ALT": "ALT", "RIGHT_ALT": "ALT"}


@lru_cache(maxsize=1)
def _glfw_names() -> dict[int, str]:
    import glfw  # core dependency; imported here so `import devices` stays light

    names: dict[int, str] = {}
    for attr in dir(glfw):
        if attr.startswith("KEY_") and attr not in ("KEY_LAST", "KEY_UNKNOWN"):
            code = getattr(glfw, attr)
            if isinstance(code, int):
                names.setdefault(code, _MODIFIERS.get(attr[4:], attr[4:]))
    return names


def glfw_key_name(key: int) -> str | None:
    """The key name used in ``key:NAME`` controls for a glfw key code (``glfw.KEY_A`` -> ``A``,
    ``glfw.KEY_LEFT_SHIFT`` -> ``SHIFT``, ``glfw.KEY_F5`` -> ``F5``); None for unknown keys. These are
    the upper-cased names render/window.py passes to its key callbacks on a US layout, so
    ``window.add_key_callback(keyboard.feed_key)`` and ``glfw_key_callback`` name keys alike."""
    return _glfw_names().get(key)


def glfw_action_name(action: int) -> KeyAction | None:
    """``glfw.PRESS/RELEASE/REPEAT`` -> ``press``/``release``/``repeat``."""
    return {1: "press", 0: "release", 2: "repeat"}.get(action)  # type: ignore[return-value]


def glfw_key_callback(device: KeyboardDevice) -> Callable[[Any, int, int, int, int], None]:
    """A callback for ``glfw.set_key_callback(window, ...)`` that feeds ``device``."""

    def callback(window: Any, key: int, scancode: int, action: int, mods: int) -> None:
        t = time.monotonic()
        name = glfw_key_name(key)
        act = glfw_action_name(action)
        if name is not None and act is not None:
            device.feed_key(name, act, t)

    return callback


class KeyboardDevice(Device):
    """Keys as 0/1 ``key`` controls named ``key:A``; auto-repeat is filtered out."""

    scheme = "keyboard"
    FORM = "keyboard://"

    def __init__(self, spec: DeviceSpec, **options: Any) -> None:
        super().__init__(spec, **options)
        if spec.location.strip("/"):  # keyboard://x was taken as the keyboard, the x ignored
            raise DeviceSpecError(f"{spec.text}: the keyboard has no address; expected {self.FORM}")
        self.description = "keyboard of the application window"
        self.controls = [ControlInfo(f"key:{n}", "key", 0.0, 1.0) for n in _NAMED]
        self._down: set[str] = set()
        self._lock = threading.Lock()

    def feed_key(self, name: str, action: KeyAction, t: float | None = None) -> None:
        """Deliver one key event from the window thread. Repeats, and presses of a key already
        down (a repeat without the flag), are dropped so a held key is one press."""
        if self._closed:
            return
        if t is None:
            t = time.monotonic()
        key = str(name).upper()
        with self._lock:
            if action == "press":
                if key in self._down:
                    return
                self._down.add(key)
                value = 1.0
            elif action == "release":
                if key not in self._down:
                    return
                self._down.discard(key)
                value = 0.0
            else:
                return
        self.emit(ControlEvent(self.spec, f"key:{key}", "key", value, None, key, t))

    def _open(self) -> None:
        """Nothing to open: the window is the hardware."""

    def _read(self, timeout: float) -> Iterable[ControlEvent]:
        self._stop.wait(timeout)
        return ()

    def _wake(self) -> None:
        self._stop.set()
