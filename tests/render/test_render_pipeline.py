"""Pipelined frames (render.pipeline): each frame's CPU half made while the frame before it
rasterises gives the serial frames' pixels, byte for byte, in order, none lost."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from render.hud import HudInfo
from render.offscreen import OffscreenRenderer
from render.pipeline import image

HUD = HudInfo(channels=[("jaw", 0.3, 0, 1)], age=30, devices=[("keyboard://", True)], fps=60.0,
              latency_ms=12.0, lines=["? help"])


@pytest.fixture(scope="module")
def surprise_onset() -> tuple[Any, list[Any]]:
    """The scanned head from rest into surprise: the lips part on the way (the mouth's inside
    starts being drawn mid-stream)."""
    from puppet.face_cache import scan_model
    from sim.facs import apply_expression
    from sim.integrator import Simulator
    from sim.state import FaceControl

    model = scan_model(None)
    sim, state = Simulator(model), model.rest_state()
    states = [state.copy()]
    for k in range(1, 8):
        control = FaceControl(model)
        apply_expression(control, "surprise", k / 7)
        for _ in range(3):
            sim.step(state, control)
        states.append(state.copy())
    return model, states


def _cameras(off: OffscreenRenderer, k: int) -> None:
    """The viewer orbits mid-stream: frames 4 and 5 from the side, the rest from the front."""
    off.renderer.camera.yaw = 0.6 if k in (4, 5) else 0.0


def _stream(off: OffscreenRenderer, states: list[Any], pipelined: bool, hud: HudInfo | None) -> list[tuple[Any, bytes]]:
    frames = off.stream(pipelined)
    out = []
    for k, s in enumerate(states):
        _cameras(off, k)
        out += frames.push(s, hud, k)
    return out + frames.finish()


@pytest.mark.parametrize("size", [(320, 180), (1280, 720)])
def test_pipelined_scanned_head_equals_serial(gl, surprise_onset, size) -> None:
    model, states = surprise_onset
    with OffscreenRenderer(model, size, ctx=gl) as off:
        serial = []
        opened = []
        for k, s in enumerate(states):
            _cameras(off, k)
            serial.append(off.render_frame(s, HUD))
            opened.append(off.renderer.scan.mouth_drawn)
        assert not opened[0] and opened[-1]  # the stream crosses the lips parting
        piped = _stream(off, states, True, HUD)
        assert gl.error == "GL_NO_ERROR"
    assert [k for k, _ in piped] == list(range(len(states)))
    for k, ((_, raw), want) in enumerate(zip(piped, serial)):
        got = image(raw, size)
        assert got.shape == want.shape
        assert np.array_equal(got, want), (size, k, int(np.abs(got.astype(int) - want).max()))
    assert len({serial[k].tobytes() for k in range(len(states))}) == len(states)  # every frame differs


def test_pipelined_mesh_face_equals_serial_in_every_view(gl, faces) -> None:
    """A face with its own mesh (not the scanned head), every view, the trails' history included."""
    from render.renderer import VIEWS

    states = faces.frames[::6]
    for view in VIEWS:
        with OffscreenRenderer(faces.model, (200, 150), view=view, ctx=gl) as off:
            serial = [off.render_frame(s, HUD) for s in states]
        with OffscreenRenderer(faces.model, (200, 150), view=view, ctx=gl) as off:
            frames = off.stream(True)
            piped = [raw for s in states for _, raw in frames.push(s, HUD)] + [raw for _, raw in frames.finish()]
        assert len(piped) == len(states)
        for k, (raw, want) in enumerate(zip(piped, serial)):
            assert np.array_equal(image(raw, (200, 150)), want), (view, k)


def test_prepared_frame_for_another_state_or_camera_is_not_used(gl, surprise_onset) -> None:
    """A CPU half made for one state, or before the camera moved, never draws another frame: the
    renderer makes the frame's own, so the picture is the serial one."""
    model, states = surprise_onset
    size = (320, 180)
    with OffscreenRenderer(model, size, ctx=gl) as off:
        r = off.renderer
        want_last = off.render_frame(states[-1])
        off.renderer.camera.yaw = 0.6
        want_turned = off.render_frame(states[-1])
        off.renderer.camera.yaw = 0.0

        def drawn(state: Any, prepared: Any) -> np.ndarray:
            off.fbo.use()
            r.draw(state, prepared=prepared)
            return image(off.fbo.read(components=3, alignment=1), size)

        assert np.array_equal(drawn(states[-1], r.prepare(states[0], size)), want_last)
        prepared = r.prepare(states[-1], size)
        off.renderer.camera.yaw = 0.6
        assert np.array_equal(drawn(states[-1], prepared), want_turned)
        off.renderer.camera.yaw = 0.0
        prepared = r.prepare(states[-1], size)
        r.prepare(states[0], size)  # made after it: its rows are gone
        assert np.array_equal(drawn(states[-1], prepared), want_last)
        assert not np.array_equal(want_last, want_turned)


def test_rasterizer_threads_steered_while_the_renderer_draws(gl, surprise_onset, monkeypatch) -> None:
    """On a machine with a core to spare, while FaceRenderer.draw sets up a frame llvmpipe's
    rasterizer threads may run only on CPUs other than the one the drawing thread was on when it
    began, and anywhere again once it returns; where other threads keep the cores busy they are
    left to the OS throughout. The pixels are the same either way."""
    import os

    from render import pipeline

    threads = pipeline.rasterizer_threads()
    cpus = set(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else set()
    if len(cpus) < 2 or not threads or not pipeline.threaded_rasterizer():
        pytest.skip("no llvmpipe rasterizer threads and two CPUs to steer them over here")
    seen: list[list[set[int]]] = []
    began: list[int] = []
    getcpu = pipeline._Steering.getcpu
    runnable = [1]  # the machine as each frame begins: this thread alone runnable

    def getcpu_seen() -> int:  # the CPU the drawing thread is on as a frame begins
        began.append(int(getcpu()))
        return began[-1]

    def flush_seen() -> None:  # where each rasterizer thread may run at each flush of the frame's parts
        seen.append([os.sched_getaffinity(t) for t in threads])
        pipeline.flush()

    monkeypatch.setattr(pipeline._Steering, "getcpu", getcpu_seen)
    monkeypatch.setattr(pipeline._Steering, "others", 0.0)
    monkeypatch.setattr(pipeline, "runnable_threads", lambda: runnable[0])
    monkeypatch.setattr("render.renderer.flush", flush_seen)
    monkeypatch.setattr("render.scan_draw.flush", flush_seen)
    model, states = surprise_onset
    pictures: dict[str, list[np.ndarray]] = {}
    with OffscreenRenderer(model, (1280, 720), ctx=gl) as off:
        pictures["steered"] = []
        for s in states[-3:]:
            seen.clear()
            pictures["steered"].append(off.render_frame(s, HUD))
            assert seen and all(t == cpus - {began[-1]} for theirs in seen for t in theirs)
            assert all(os.sched_getaffinity(t) == cpus for t in threads) and os.sched_getaffinity(0) == cpus
        runnable[0] = 1 + 8 * len(cpus)  # other programs' threads keep every core busy
        pictures["loaded"] = []
        for s in states[-3:]:
            seen.clear()
            pictures["loaded"].append(off.render_frame(s, HUD))
        assert all(t == cpus for theirs in seen for t in theirs)  # the last frames: left to the OS
        off.renderer.steer = False
        try:
            seen.clear()
            pictures["free"] = [off.render_frame(s, HUD) for s in states[-3:]]
            assert seen and all(t == cpus for theirs in seen for t in theirs)
        finally:
            off.renderer.steer = True
    for k in range(3):
        assert np.array_equal(pictures["steered"][k], pictures["free"][k])
        assert np.array_equal(pictures["loaded"][k], pictures["free"][k])
