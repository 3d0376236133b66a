"""An OSMesa context with a float32 framebuffer that tells which triangle covers each pixel.

pyrender's OSMesa context renders into an 8-bit colour buffer, so Depict borrows its OSMesa
platform for the OpenGL context only and rasterises into a framebuffer object of its own (a
``GL_RGBA32F`` colour attachment and a ``GL_DEPTH_COMPONENT32F`` depth buffer) with a tiny shader
that writes, at each pixel centre, the index of the visible triangle (``gl_PrimitiveID``, as two
exact 16-bit halves), read back with ``glReadPixels(GL_FLOAT)``.
"""

from __future__ import annotations

import os
import sys
import threading
from typing import Any, Self

import numpy as np

from gbuffer.errors import FrameError

if "OpenGL" not in sys.modules:  # must be set before PyOpenGL is first imported
    os.environ.setdefault("PYOPENGL_PLATFORM", "osmesa")

_VERTEX_SHADER = """#version 330 core
layout(location = 0) in vec3 a_pos;
uniform mat4 u_proj;
void main() {
    gl_Position = u_proj * vec4(a_pos, 1.0);
}
"""

# the triangle drawn at each pixel centre, as two exact float halves (ids < 2^32)
_FRAGMENT_SHADER = """#version 330 core
layout(location = 0) out vec4 o_id;
void main() {
    uint id = uint(gl_PrimitiveID);
    o_id = vec4(float(id & 0xFFFFu), float(id >> 16u), 1.0, 0.0);
}
"""


class TriangleIds:
    """An OSMesa context with a float32 framebuffer; draws triangles into an image of their ids.

    One instance is reusable across meshes and sizes (the framebuffer is reallocated when the size
    changes; creating the context is the expensive part). Thread-safe (one render at a time).
    Call :meth:`delete` (or use it as a context manager) to free the context.
    """

    def __init__(self) -> None:
        self._lock = threading.RLock()
        self._platform: Any = None
        self._program: Any = None
        self._vao: Any = None
        self._fbo: Any = None
        self._renderbuffers: list[Any] = []
        self._size: tuple[int, int] | None = None

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.delete()

    def _context(self) -> Any:
        """Make the context current (creating it on first use); returns the GL module."""
        platform_name = os.environ.get("PYOPENGL_PLATFORM", "osmesa")
        if platform_name != "osmesa":
            raise FrameError(
                f"mesh rendering needs PYOPENGL_PLATFORM=osmesa (it is {platform_name!r}); "
                "unset it or import gbuffer.render before anything imports OpenGL"
            )
        if not hasattr(np, "infty"):  # pyrender 0.1.45 still uses np.infty
            setattr(np, "infty", np.inf)  # noqa: B010
        try:
            from OpenGL import GL as gl
            from OpenGL.GL import shaders
            from pyrender.platforms.osmesa import OSMesaPlatform
        except Exception as exc:
            raise FrameError(f"OpenGL/OSMesa is not available for mesh rendering: {exc}") from exc
        if self._platform is None:
            platform = OSMesaPlatform(1, 1)
            try:
                platform.init_context()
                platform.make_current()
            except Exception as exc:
                raise FrameError(
                    f"cannot create an OSMesa context (install libosmesa6): {exc}"
                ) from exc
            self._platform = platform
            self._program = shaders.compileProgram(
                shaders.compileShader(_VERTEX_SHADER, gl.GL_VERTEX_SHADER),
                shaders.compileShader(_FRAGMENT_SHADER, gl.GL_FRAGMENT_SHADER),
                validate=False,
            )
            self._vao = gl.glGenVertexArrays(1)
        else:
            self._platform.make_current()
        return gl

    def _target(self, gl: Any, width: int, height: int) -> None:
        if self._size == (width, height):
            gl.glBindFramebuffer(gl.GL_FRAMEBUFFER, self._fbo)
            return
        self._free_target(gl)
        self._fbo = gl.glGenFramebuffers(1)
        gl.glBindFramebuffer(gl.GL_FRAMEBUFFER, self._fbo)
        rbs = list(np.atleast_1d(gl.glGenRenderbuffers(2)))
        gl.glBindRenderbuffer(gl.GL_RENDERBUFFER, rbs[0])
        gl.glRenderbufferStorage(gl.GL_RENDERBUFFER, gl.GL_RGBA32F, width, height)
        gl.glFramebufferRenderbuffer(
            gl.GL_FRAMEBUFFER, gl.GL_COLOR_ATTACHMENT0, gl.GL_RENDERBUFFER, rbs[0]
        )
        gl.glBindRenderbuffer(gl.GL_RENDERBUFFER, rbs[1])
        gl.glRenderbufferStorage(gl.GL_RENDERBUFFER, gl.GL_DEPTH_COMPONENT32F, width, height)
        gl.glFramebufferRenderbuffer(
            gl.GL_FRAMEBUFFER, gl.GL_DEPTH_ATTACHMENT, gl.GL_RENDERBUFFER, rbs[1]
        )
        self._renderbuffers = rbs
        status = gl.glCheckFramebufferStatus(gl.GL_FRAMEBUFFER)
        if status != gl.GL_FRAMEBUFFER_COMPLETE:
            self._free_target(gl)
            raise FrameError(f"float framebuffer {width}x{height} is incomplete (status {status})")
        self._size = (width, height)

    def _free_target(self, gl: Any) -> None:
        if self._fbo is not None:
            gl.glBindFramebuffer(gl.GL_FRAMEBUFFER, 0)
            gl.glDeleteFramebuffers(1, [self._fbo])
            gl.glDeleteRenderbuffers(len(self._renderbuffers), self._renderbuffers)
        self._fbo, self._renderbuffers, self._size = None, [], None

    def delete(self) -> None:
        """Free the framebuffer and the OSMesa context (a later render creates them again)."""
        with self._lock:
            if self._platform is None:
                return
            try:
                gl = self._context()
                self._free_target(gl)
                if self._program is not None:
                    gl.glDeleteProgram(self._program)
                if self._vao is not None:
                    gl.glDeleteVertexArrays(1, [self._vao])
            finally:
                self._platform.delete_context()
                self._platform = self._program = self._vao = None

    def draw(self, corners: np.ndarray, proj: np.ndarray, width: int, height: int) -> np.ndarray:
        """(H, W) int64 index of the triangle at each pixel centre (row 0 at the top), −1 = none.

        ``corners`` (3 T, 3) float32: the triangles' corners, projected by ``proj`` (4 × 4)."""
        gl = self._context()
        self._target(gl, width, height)
        gl.glViewport(0, 0, width, height)
        gl.glDrawBuffers(1, [gl.GL_COLOR_ATTACHMENT0])
        gl.glDisable(gl.GL_CULL_FACE)
        gl.glDisable(gl.GL_BLEND)
        gl.glEnable(gl.GL_DEPTH_TEST)
        gl.glDepthFunc(gl.GL_LESS)
        gl.glClearColor(0.0, 0.0, 0.0, 0.0)
        gl.glClearDepth(1.0)
        gl.glClear(gl.GL_COLOR_BUFFER_BIT | gl.GL_DEPTH_BUFFER_BIT)
        gl.glUseProgram(self._program)
        gl.glUniformMatrix4fv(gl.glGetUniformLocation(self._program, "u_proj"), 1, gl.GL_TRUE, proj)
        gl.glBindVertexArray(self._vao)
        buffer = gl.glGenBuffers(1)
        try:
            arr = np.ascontiguousarray(corners, np.float32)
            gl.glBindBuffer(gl.GL_ARRAY_BUFFER, buffer)
            gl.glBufferData(gl.GL_ARRAY_BUFFER, arr.nbytes, arr, gl.GL_STREAM_DRAW)
            gl.glEnableVertexAttribArray(0)
            gl.glVertexAttribPointer(0, 3, gl.GL_FLOAT, False, 0, None)
            gl.glDrawArrays(gl.GL_TRIANGLES, 0, len(arr))
            gl.glReadBuffer(gl.GL_COLOR_ATTACHMENT0)
            raw = gl.glReadPixels(0, 0, width, height, gl.GL_RGBA, gl.GL_FLOAT)
            err = gl.glGetError()
            if err != gl.GL_NO_ERROR:
                raise FrameError(f"OpenGL error {err} while rendering")
        finally:
            gl.glDisableVertexAttribArray(0)
            gl.glBindBuffer(gl.GL_ARRAY_BUFFER, 0)
            gl.glDeleteBuffers(1, [buffer])
            gl.glBindVertexArray(0)
        rgba = np.asarray(raw, np.float32).reshape(height, width, 4)[::-1]  # GL row 0: bottom
        ids = rgba[..., 0].astype(np.int64) + (rgba[..., 1].astype(np.int64) << 16)
        ids[rgba[..., 2] < 0.5] = -1
        return ids
