"""The face as a stream for a remote renderer (the performer's page draws it with WebGL 2): what the
renderer draws, split into what never changes (`FaceStream.scene`: triangles, colours, the rest
places, the cavities, the eyes, the camera, the shaders) and what changes per frame
(`FaceStream.frame`: the drawn vertices' positions, quantised, and the gaze).

The streamed vertices are the rows the renderer uploads (the mask's surface and the held head's
vertices posed to it, `render.meshdata.SurfaceRows`) followed by the cavities' vertices, whatever
the face's mesh is; the page computes the normals itself from the positions and the same triangles
(area-weighted, the join's vertices taking the mask's normals, as `SurfaceRows` does). Positions
go as int16 steps of `QUANTUM` cm from the rest places, deflated (zlib) once per frame for every
page: a face at rest, or a head that does not move, is nearly all zeros. The shaders are the
renderer's own GLSL (render.shaders) with the header of GLSL ES 3.00, so the page lights the face
as the show does.

The other way (`picture`): a picture of the face as the show renders it, JPEG-encoded once per
frame for every page (kind 3). A page then only decodes a small image: its cost does not grow with
the mesh, and the server's does not grow with the number of pages (benchmarks/panel_face.py).

Binary messages: byte 0 the kind (1 scene, 2 frame, 3 picture), bytes 4..7 the JSON header's length (uint32,
little-endian), the header (UTF-8, padded with spaces to a multiple of 8), then the payload: the
scene's arrays at the offsets its header lists; the frame's deflated int16 (V, 3) array."""

from __future__ import annotations

import json
import struct
import zlib
from typing import Any

import numpy as np

from render import shaders
from render.camera import OrbitCamera
from render.meshdata import HAIR, SKIN, brow_coords, skin_tint, surface_rows, uv_sphere
from render.renderer import BACKGROUND, EYE_PITCH_MAX, EYE_YAW_MAX, IMPORTED, face_cavities

SCENE, FRAME, PICTURE = 1, 2, 3
QUANTUM = 0.002  # cm per int16 step: 20 um, a 50th of a pixel on a page's face; range +-65 cm
ASPECT = 4.0 / 3.0  # the page's face view
PICTURE_SIZE = (400, 300)  # the page's face view when it is sent as pictures (ASPECT), unless it asks
# the sizes a page may ask for (ASPECT): the smallest one at least as wide as the page shows the face;
# every page of one size shares its picture, so the server makes at most this many a frame
PICTURE_SIZES = ((160, 120), (240, 180), (320, 240), (400, 300), (480, 360), (640, 480))
PICTURE_QUALITY = 80  # JPEG quality: 8-12 KB a frame for the scanned head at PICTURE_SIZE
ES_HEADER = "#version 300 es\nprecision highp float;\nprecision highp int;\n"


def _es(src: str) -> str:
    """A desktop GLSL 3.30 source of render.shaders as GLSL ES 3.00 (WebGL 2)."""
    return src.replace(shaders.HEADER, ES_HEADER, 1)


def pack(kind: int, header: dict[str, Any], payload: bytes = b"") -> bytes:
    """One binary message: kind, header length, JSON header padded to 8 bytes, payload."""
    text = json.dumps(header, separators=(",", ":")).encode()
    text += b" " * (-(len(text) + 8) % 8)
    return struct.pack("<B3xI", kind, len(text)) + text + payload


def unpack(msg: bytes) -> tuple[int, dict[str, Any], bytes]:
    """(kind, header, payload) of a message made by `pack` (tests and benchmarks read them)."""
    kind, n = struct.unpack_from("<B3xI", msg)
    return kind, json.loads(msg[8:8 + n]), msg[8 + n:]


def encode_positions(positions: np.ndarray, base: np.ndarray, out: np.ndarray | None = None,
                     level: int = 1) -> bytes:
    """(V, 3) positions as deflated int16 steps of QUANTUM cm from `base` (a frame's payload)."""
    d = (np.asarray(positions, np.float32) - base) * np.float32(1.0 / QUANTUM)
    np.clip(np.rint(d, out=d), -32767, 32767, out=d)
    q = out if out is not None else np.empty(d.shape, np.int16)
    q[...] = d
    return zlib.compress(q.tobytes(), level)


def picture_size(width: float) -> tuple[int, int]:
    """The picture size for a page that shows the face `width` device pixels wide: the smallest of
    PICTURE_SIZES at least that wide (the largest for a wider view); PICTURE_SIZE when it does not say."""
    if not isinstance(width, (int, float)) or not width > 0:
        return PICTURE_SIZE
    for size in PICTURE_SIZES:
        if size[0] >= width:
            return size
    return PICTURE_SIZES[-1]


def pictures(pixels: np.ndarray, face_id: str, tick: int, t: float, sizes: Any = (PICTURE_SIZE,),
             quality: int = PICTURE_QUALITY) -> dict[tuple[int, int], bytes]:
    """The picture message (`picture`) of `pixels` at each of `sizes`: cropped once, each size
    scaled from the crop and encoded once (every page of that size gets the same bytes)."""
    import io

    from PIL import Image

    h, w = pixels.shape[:2]
    out: dict[tuple[int, int], bytes] = {}
    crop: Any = None
    for size in sorted({(int(a), int(b)) for a, b in sizes}, reverse=True):
        if crop is None:
            aspect = size[0] / size[1]
            cw, ch = (min(w, int(round(h * aspect))), min(h, int(round(w / aspect))))
            x0, y0 = (w - cw) // 2, (h - ch) // 2
            crop = Image.fromarray(np.ascontiguousarray(pixels[y0:y0 + ch, x0:x0 + cw, :3]))
        img = crop if crop.size == size else crop.resize(size, Image.Resampling.BILINEAR, reducing_gap=2.0)
        buf = io.BytesIO()
        img.save(buf, "JPEG", quality=int(quality))
        header = {"face": face_id, "tick": int(tick), "t": round(float(t), 6), "w": size[0], "h": size[1],
                  "type": "image/jpeg"}
        out[size] = pack(PICTURE, header, buf.getvalue())
    return out


def picture(pixels: np.ndarray, face_id: str, tick: int, t: float, size: tuple[int, int] = PICTURE_SIZE,
            quality: int = PICTURE_QUALITY) -> bytes:
    """One picture message: (H, W, 3) uint8 `pixels` of the face (top row first) cropped about
    the centre to the page's aspect, scaled to `size` and JPEG-encoded; the header carries the tick
    shown, the server's time `t` (time.monotonic) it was drawn, and the image's size and type."""
    size = (int(size[0]), int(size[1]))
    return pictures(pixels, face_id, tick, t, (size,), quality)[size]


def _colmajor(m: np.ndarray) -> list[float]:
    return [float(x) for x in np.asarray(m, np.float64).T.ravel()]


class FaceStream:
    """Encoder of one face model for remote renderers; `scene()` once per page (and whenever the
    face changes: its `face_id` tells the page), `frame(state, tick, t)` per frame."""

    def __init__(self, model: Any, face_id: str = "face") -> None:
        self.model, self.face_id = model, face_id
        mesh = model.mesh
        rest = np.asarray(model.rest, np.float32)
        self.rows = surface_rows(model)
        n = self.rows.n
        rows_rest = np.array(self.rows.interleaved(rest)[:, :3], np.float32)
        self.n_rows = len(rows_rest)
        tint = skin_tint(mesh).astype(np.float32)
        color, rest_attr, brow = tint, rest, brow_coords(mesh).astype(np.float32)
        shell = self.rows.shell
        head_tris = np.zeros((0, 3), np.int32)
        self.camera = OrbitCamera()
        lo, hi = rest.min(axis=0), rest.max(axis=0)
        if shell is not None:  # as FaceRenderer._populate_head: colours, rest, hair coordinates
            v = np.asarray(shell.vertices, np.float32)
            col = np.tile(SKIN, (len(v), 1)).astype(np.float32)
            col[shell.ring] = tint[shell.ring_mask]
            vrest = v.copy()
            vrest[shell.ring] = rest[shell.ring_mask]
            color = np.vstack([tint, col])
            rest_attr = np.vstack([rest, vrest])
            brow = np.vstack([brow, np.asarray(shell.hair_coords, np.float32)])
            head_tris = np.asarray(shell.triangles, np.int32) + n
            seen = v[v[:, 1] > lo[1] - 3.0]
            lo, hi = np.minimum(lo, seen.min(axis=0)), np.maximum(hi, seen.max(axis=0))
        self.camera.fit(lo, hi)
        # the cavities behind the mouth and the eye openings, streamed after the rows
        self.cavities, cav_tris, depth, teeth, rims, _ = face_cavities(
            mesh, rest, self.n_rows, dentition=str(getattr(model.rig, "presets", "")).startswith(IMPORTED))
        self.base = np.vstack([rows_rest, *self._cavity_positions(rest)]).astype(np.float32)
        self.n_vertices = len(self.base)
        if self.rows.shell is not None:
            copy_dst, copy_src = np.asarray(self.rows.ring, np.int32), np.asarray(self.rows.ring_mask, np.int32)
        else:
            copy_dst = copy_src = np.zeros(0, np.int32)
        sphere, sphere_tris = uv_sphere(12, 20)
        self._arrays: dict[str, np.ndarray] = {
            "base": self.base,
            "color": color.astype(np.float32), "rest": rest_attr.astype(np.float32), "brow": brow.astype(np.float32),
            "skin_tris": np.asarray(model.triangles, np.uint32).ravel(),
            "head_tris": head_tris.astype(np.uint32).ravel(),
            "normal_tris": np.asarray(self.rows.normals.tri, np.uint32).ravel(),
            "copy_dst": copy_dst.astype(np.uint32), "copy_src": copy_src.astype(np.uint32),
            "cavity_tris": (np.concatenate(cav_tris) if cav_tris else np.zeros((0, 3))).astype(np.uint32).ravel(),
            "cavity_depth": (np.concatenate(depth) if depth else np.zeros(0)).astype(np.float32),
            "cavity_teeth": (np.concatenate(teeth) if teeth else np.zeros(0)).astype(np.float32),
            "cavity_rim": (np.concatenate(rims) if rims else np.zeros((0, 3))).astype(np.float32),
            "sphere": np.asarray(sphere, np.float32), "sphere_tris": np.asarray(sphere_tris, np.uint32).ravel(),
        }
        self._scene: bytes | None = None
        self._q = np.empty((self.n_vertices, 3), np.int16)

    def _cavity_positions(self, surface: np.ndarray) -> list[np.ndarray]:
        return [np.asarray(c.positions(surface), np.float32) for c in self.cavities]

    def scene(self) -> bytes:
        """The message a page needs before frames: made once, the same bytes for every page."""
        if self._scene is None:
            from sim.face.head import HAIR_EDGE

            view, proj = self.camera.matrices(ASPECT)
            blobs, parts, offset = {}, [], 0
            for name, arr in self._arrays.items():
                raw = np.ascontiguousarray(arr).tobytes()
                blobs[name] = [str(arr.dtype), offset, int(arr.size)]
                raw += b"\0" * (-len(raw) % 8)
                parts.append(raw)
                offset += len(raw)
            mesh = self.model.mesh
            header = {
                "face": self.face_id, "vertices": self.n_vertices, "rows": self.n_rows, "mask": self.rows.n,
                "quantum": QUANTUM, "blobs": blobs, "aspect": ASPECT,
                "view": _colmajor(view), "mvp": _colmajor(proj @ view), "background": list(BACKGROUND),
                "eyes": {"centers": np.asarray(mesh.eye_centers, float).tolist(), "radius": float(mesh.eye_radius),
                         "yaw_max": EYE_YAW_MAX, "pitch_max": EYE_PITCH_MAX},
                "hair": {"albedo": [float(c) for c in HAIR], "edge": [float(x) for x in HAIR_EDGE]},
                "shaders": {"skin_vs": _es(shaders.skin_source("SKIN", vertex=True)),
                            "skin_fs": _es(shaders.skin_source("SKIN")),
                            "scalp_vs": _es(shaders.skin_source("SCALP", vertex=True)),
                            "scalp_fs": _es(shaders.skin_source("SCALP")),
                            "eye_vs": _es(shaders.EYE_VS), "eye_fs": _es(shaders.EYE_FS),
                            "cavity_vs": _es(shaders.CAVITY_VS), "cavity_fs": _es(shaders.CAVITY_FS)},
            }
            self._scene = pack(SCENE, header, b"".join(parts))
        return self._scene

    def positions(self, state: Any) -> np.ndarray:
        """(V, 3) float32 positions of every streamed vertex for `state` (what the page receives,
        before quantisation)."""
        surface = np.asarray(state.surface, np.float32)
        if self.rows.shell is None:
            rows = surface
        else:
            self.rows.positions[:self.rows.n] = surface
            self.rows.positions[self.rows.n:] = self.rows.shell.pose(surface)
            rows = self.rows.positions
        return np.vstack([rows, *self._cavity_positions(surface)])

    def frame(self, state: Any, tick: int, t: float, level: int = 1) -> bytes:
        """One frame message: the tick it shows, the server's time `t` (time.monotonic) the state
        was read, the gaze, and the deflated int16 positions (steps of QUANTUM from the rest)."""
        payload = encode_positions(self.positions(state), self.base, self._q, level)
        header = {"face": self.face_id, "tick": int(tick), "t": round(float(t), 6),
                  "eye": [float(getattr(state, "eye_yaw", 0.0)), float(getattr(state, "eye_pitch", 0.0)),
                          float(getattr(state, "eye_vergence", 0.0))]}
        return pack(FRAME, header, payload)

    def decode(self, msg: bytes) -> np.ndarray:
        """(V, 3) float32 positions of a frame message, as a page reconstructs them."""
        kind, header, payload = unpack(msg)
        if kind != FRAME:
            raise ValueError("not a frame message")
        q = np.frombuffer(zlib.decompress(payload), np.int16).reshape(-1, 3)
        return self.base + q.astype(np.float32) * QUANTUM
