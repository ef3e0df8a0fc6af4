"""keyboard://: repeat filtering, glfw key names, and real key presses through Xvfb + xdotool."""

from __future__ import annotations

import os
import subprocess
import time

import glfw
import pytest

from devices import ControlEvent, EventQueue, open_device
from devices.keyboard import KeyboardDevice, glfw_key_callback, glfw_key_name


def _key_events(q: EventQueue) -> list[tuple[str, float]]:
    return [(e.control, e.value) for e in q.drain() if isinstance(e, ControlEvent)]


def test_repeats_and_double_presses_are_filtered() -> None:
    dev = open_device("keyboard://")
    assert isinstance(dev, KeyboardDevice)
    q = EventQueue()
    dev.add_listener(q)
    dev.feed_key("a", "press", 1.0)
    dev.feed_key("A", "repeat", 1.1)
    dev.feed_key("A", "press", 1.2)  # a repeat that lost its flag
    dev.feed_key("A", "release", 1.3)
    dev.feed_key("A", "release", 1.4)
    events = q.drain()
    assert [(e.control, e.value, e.t) for e in events] == [("key:A", 1.0, 1.0), ("key:A", 0.0, 1.3)]
    assert all(e.kind == "key" and e.device == "keyboard://" for e in events)
    dev.close()
    dev.feed_key("B", "press", 2.0)  # a window outliving the device must not reach its listeners
    assert q.drain() == []


def test_glfw_key_names() -> None:
    assert glfw_key_name(glfw.KEY_A) == "A"
    assert glfw_key_name(glfw.KEY_7) == "7"
    assert glfw_key_name(glfw.KEY_LEFT_SHIFT) == glfw_key_name(glfw.KEY_RIGHT_SHIFT) == "SHIFT"
    assert glfw_key_name(glfw.KEY_F5) == "F5"
    assert glfw_key_name(-12345) is None


def test_keys_typed_into_a_glfw_window_under_xvfb(xvfb_display: str, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("DISPLAY", xvfb_display)
    assert glfw.init(), "glfw could not connect to Xvfb"
    try:
        glfw.window_hint(glfw.CLIENT_API, glfw.NO_API)
        window = glfw.create_window(200, 100, "keys", None, None)
        assert window
        dev = open_device("keyboard://")
        q = EventQueue()
        dev.add_listener(q)
        glfw.set_key_callback(window, glfw_key_callback(dev))  # type: ignore[arg-type]
        glfw.show_window(window)
        wid = str(glfw.get_x11_window(window))
        for _ in range(20):
            glfw.poll_events()
        env = {**os.environ, "DISPLAY": xvfb_display}
        subprocess.run(["xdotool", "key", "--window", wid, "a", "b", "space"], check=True, env=env, timeout=10)
        got: list[tuple[str, float]] = []
        deadline = time.monotonic() + 5
        while len(got) < 6 and time.monotonic() < deadline:
            glfw.wait_events_timeout(0.05)
            got += _key_events(q)
        assert got == [("key:A", 1.0), ("key:A", 0.0), ("key:B", 1.0), ("key:B", 0.0),
                       ("key:SPACE", 1.0), ("key:SPACE", 0.0)]
        dev.close()
        glfw.destroy_window(window)
    finally:
        glfw.terminate()
