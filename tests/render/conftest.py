"""One EGL context for the whole render test session (creating contexts is slow on llvmpipe), checked
for GL errors around every test, and the faces the tests draw."""

from __future__ import annotations

from collections.abc import Iterator

import moderngl
import pytest
from render_faces import Faces, simulate_faces

from render.offscreen import OffscreenRenderer, create_context


@pytest.fixture(scope="session")
def gl_session() -> Iterator[moderngl.Context]:
    ctx = create_context()
    yield ctx
    ctx.release()


@pytest.fixture()
def gl(gl_session: moderngl.Context) -> Iterator[moderngl.Context]:
    """The shared context, asserting no GL error is left before or after the test."""
    assert gl_session.error == "GL_NO_ERROR"
    yield gl_session
    assert gl_session.error == "GL_NO_ERROR"


@pytest.fixture(scope="session")
def faces() -> Faces:
    return simulate_faces()


@pytest.fixture()
def offscreen(gl: moderngl.Context, faces: Faces) -> Iterator[OffscreenRenderer]:
    off = OffscreenRenderer(faces.model, (200, 150), ctx=gl)
    yield off
    off.release()
