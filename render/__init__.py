"""Draws a face state with moderngl. Only `render.window` (glfw) and `render.offscreen` (EGL)
create OpenGL contexts."""
