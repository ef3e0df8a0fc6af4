"""Every format the program reads: a good file, its damaged variants, and the real command that
reads it, run in this process (`puppet.cli.main`) so hundreds of variants stay fast.

`outcome(...)` says what a user would have seen: "ok" (exit 0), "error" (exit 2 and one short line
naming the file) or "traceback" (anything else: an exception escaping the command, a message of
several lines or thousands of characters, an --out file that changed)."""

from __future__ import annotations

import contextlib
import io
import json
import tempfile
import traceback
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import damage

MAX_LINE = 400
OLD = b"the user's old file\n"


@dataclass
class Outcome:
    kind: str  # ok | error | traceback
    text: str


def old_output(out: Path) -> Path:
    """The user's earlier export at `out` (a frames folder when named "frames"): the file an export
    must leave as it was if it fails; returns it."""
    if out.name == "frames":
        out.mkdir()
        out = out / "frame_000000.png"
    out.write_bytes(OLD)
    return out


def run_cli(argv: list[str], file: Path, outs: tuple[Path, ...] = (), also: str = "") -> Outcome:
    """Run `puppet ARGV` here; classify what the user sees. `outs` hold OLD before the run and
    must still hold it after a failed run. The error line must name `file` (or `also`)."""
    from puppet.cli import main

    for o in outs:
        o.write_bytes(OLD)
    err = io.StringIO()
    try:
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            rc = main(argv)
    except SystemExit as e:  # argparse
        rc = e.code if isinstance(e.code, int) else 2
    except BaseException:  # noqa: BLE001 - what we count
        lost = [o.name for o in outs if not o.exists() or o.read_bytes() != OLD]
        return Outcome("traceback", traceback.format_exc(limit=-3) + (f"\n(and destroyed {lost[0]})" if lost else ""))
    text = err.getvalue()
    if rc == 0:
        return Outcome("ok", text)
    for o in outs:
        if not o.exists() or o.read_bytes() != OLD:
            return Outcome("traceback", f"failed, and destroyed {o.name}: {text[-300:]}")
    lines = [ln for ln in text.splitlines() if ln.startswith("puppet: error:")]
    if rc != 2 or len(lines) != 1:
        return Outcome("traceback", f"exit {rc}: {text[-2000:]}")
    line = lines[0]
    if len(line) > MAX_LINE:
        return Outcome("traceback", f"error line of {len(line)} chars: {line[:200]}")
    if file.name not in line and not (also and also in line):
        return Outcome("traceback", f"error line does not name {file.name}: {line}")
    return Outcome("error", line)


@dataclass
class Format:
    """A file format: how to make a good file in a folder, its variants, and how to read one."""

    name: str
    suffix: str
    good: Callable[[Path], bytes]
    variants: Callable[[bytes], Iterator[damage.Variant]]
    read: Callable[[Path, Path], Outcome]  # (file, work folder) -> outcome
    refused: float = 0.25  # at least this share of the variants must be refused (damaged sound still plays)


# ------------------------------------------------------------------------------ good files

def good_recording(d: Path) -> bytes:
    import numpy as np

    import sim.face
    from puppet.session import SessionWriter

    model = sim.face.default_model(0)
    from puppet.live import load_face

    face = load_face(None, 0)
    names = [c.name for c in face.vocab.channels]
    header = {"program": "facepuppet test", "rig": face.rig, "channels": names, "tick_rate": 60.0,
              "mapping": {"source": "test", "text": ""}, "devices": ["mock://"]}
    p = d / "good.jsonl"
    vals = np.array(face.vocab.defaults(), dtype=np.float64)
    jaw = names.index("jaw")
    with SessionWriter(p, header) as w:
        for k in range(24):
            vals[jaw] = 0.02 * k
            w.values(k, vals)
            if k == 10:
                w.marker(k, "half")
            w.tick(k + 1)
        w.flush()
        w.close(24)
    assert model is not None
    return p.read_bytes()


def good_mapping(d: Path) -> bytes:
    return (Path(__file__).parents[2] / "puppet" / "maps" / "sgi.toml").read_bytes()


def good_curves(d: Path) -> bytes:
    return (b"facepuppet-curves 1\n# a smile and a jaw\ncurve zygomaticus_major smooth replace\n"
            b"  0.000  0\n  0.200  0.8\n  0.400  0.1\nend\ncurve jaw linear add\n  0.0 0\n  0.3 0.5\nend\n"
            b"curve AU12 step max\n 0.1 0.5\n 0.2 1\nend\n")


def good_curves_v2(d: Path) -> bytes:
    """Version 2, as the force-graph editor saves it: an interpolation per key, a hold, a step."""
    return (b"facepuppet-curves 2\n# saved by the editor\ncurve zygomaticus_major smooth replace\n"
            b"  0.000000  0\n  0.200000  0.8  linear\n  0.300000  0.8  step\n  0.400000  0.1\nend\n"
            b"curve jaw linear add\n  0.000000  0  smooth\n  0.300000  0.5\nend\n"
            b"curve AU12 step max\n  0.100000  0.5\n  0.200000  1  smooth\nend\n")


def good_rig(d: Path) -> bytes:
    from sim.face import default_rig
    from sim.rig import save_rig

    p = d / "good.npz"
    save_rig(default_rig(0), p)
    return p.read_bytes()


def good_mock_toml(d: Path) -> bytes:
    return (b'counts_per_turn = 200\nspeed = 0\n\n[[controls]]\nname = "fader"\nkind = "axis"\nlo = 0.0\n'
            b'hi = 1.0\n\n[[events]]\nt = 0.0\ncontrol = "fader"\nvalue = 0.5\n\n[[events]]\nt = 0.01\n'
            b'control = "dial0"\ndelta = 12\n\n[[ramp]]\ncontrol = "fader"\nstart = 0.02\nduration = 0.02\n'
            b'from = 0.0\nto = 1.0\nrate = 100\n\n[[sine]]\ncontrol = "knob1"\nduration = 0.02\nfreq = 2.0\n'
            b'rate = 100\n\n[[pattern]]\ncontrol = "button1"\nperiod = 0.01\nduty = 0.5\ncount = 2\n\n'
            b'[[status]]\nt = 0.03\nstatus = "lost"\n')


def good_mock_json(d: Path) -> bytes:
    import tomllib

    return json.dumps(tomllib.loads(good_mock_toml(d).decode()), indent=1).encode()


def good_dbc(d: Path) -> bytes:
    return (Path(__file__).parents[2] / "examples" / "can" / "panel.dbc").read_bytes()


def _head() -> tuple:
    from sim.face.builder import build_face_mesh

    mesh = build_face_mesh(0)
    return mesh.vertices, mesh.triangles, {k: int(v) for k, v in mesh.landmarks.items()}


def good_obj(d: Path) -> bytes:
    v, t, _ = _head()
    lines = [f"v {x:.5f} {y:.5f} {z:.5f}" for x, y, z in v[:120]]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in t if max(a, b, c) < 120][:150]
    return ("\n".join(lines) + "\n").encode()


def _trimesh_bytes(kind: str, **kw: object) -> bytes:
    import numpy as np
    import trimesh

    v, t, _ = _head()
    keep = np.all(t < 120, axis=1)
    m = trimesh.Trimesh(v[:120], t[keep][:150], process=False)
    return m.export(file_type=kind, **kw)  # type: ignore[return-value]


def good_ply(d: Path) -> bytes:
    return _trimesh_bytes("ply", encoding="ascii")


def good_ply_bin(d: Path) -> bytes:
    return _trimesh_bytes("ply")


def good_off(d: Path) -> bytes:
    data: bytes | str = _trimesh_bytes("off")  # trimesh exports OFF as text
    return data.encode() if isinstance(data, str) else data


def good_glb(d: Path) -> bytes:
    return _trimesh_bytes("glb")


def good_stl(d: Path) -> bytes:
    return _trimesh_bytes("stl")


def good_landmarks(d: Path) -> bytes:
    verts, _, lms = _head()
    data = {k: (v if i % 2 else [round(float(c), 6) for c in verts[v]]) for i, (k, v) in enumerate(sorted(lms.items()))}
    return json.dumps({"landmarks": data}, indent=1).encode()


# ------------------------------------------------------------------------------ readers

def read_recording(f: Path, d: Path) -> Outcome:
    out = d / "take.csv"
    return run_cli(["replay", str(f), "--out", str(out)], f, (out,))


def read_recording_headless(f: Path, d: Path) -> Outcome:
    return run_cli(["replay", str(f), "--headless"], f)


def read_curves(f: Path, d: Path) -> Outcome:
    out = d / "curves.arkit.csv"
    return run_cli(["replay", "--curves", str(f), "--out", str(out)], f, (out,))


def read_rig(f: Path, d: Path) -> Outcome:
    out = d / "pose.obj"
    return run_cli(["pose", "--rig", str(f), "--seconds", "0", "--out", str(out)], f, (out,))


def read_mapping(f: Path, d: Path) -> Outcome:
    """The mapping as `puppet live --map` reads it, and as `puppet learn` rewrites it."""
    from puppet.errors import PuppetError
    from puppet.live import build_mapping, load_face

    try:
        from safefile import BadFile
    except ImportError:  # measuring the program as it was before safefile
        BadFile = PuppetError  # noqa: N806
    face = load_face(None, 0)
    try:
        build_mapping(face.vocab, str(f), [])
    except (PuppetError, BadFile) as err:
        line = str(err)
        if "\n" in line or len(line) > MAX_LINE or f.name not in line:
            return Outcome("traceback", f"bad error line: {line[:300]}")
        return Outcome("error", line)
    except BaseException:  # noqa: BLE001
        return Outcome("traceback", traceback.format_exc(limit=-3))
    return Outcome("ok", "")


def read_mock(f: Path, d: Path) -> Outcome:
    return run_cli(["monitor", f"mock://{f}?speed=0", "--duration", "0"], f)


def read_dbc(f: Path, d: Path) -> Outcome:
    return run_cli(["monitor", f"can://virtual/fuzz{abs(hash(f)) % 1000}?dbc={f}", "--duration", "0"], f)


def read_mesh(f: Path, d: Path) -> Outcome:
    """import-face with a landmark file that lacks most landmarks: the mesh is read and checked,
    then the command stops quickly at the landmarks."""
    lm = d / "few.json"
    if not lm.exists():
        lm.write_text(json.dumps({"nose_tip": 3}))
    out = d / "head.npz"
    r = run_cli(["import-face", str(f), "--landmarks", str(lm), "--out", str(out), "--no-image"], f, (out,),
                also="few.json")
    if r.kind == "error" and "few.json: missing landmark" in r.text:
        return Outcome("ok", r.text)  # the mesh itself was read
    return r


def read_landmarks(f: Path, d: Path) -> Outcome:
    mesh = d / "lm-head.obj"
    if not mesh.exists():
        v, t, _ = _head()
        lines = [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in v] + [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in t]
        mesh.write_text("\n".join(lines) + "\n")
    out = d / "lm.npz"
    return run_cli(["import-face", str(mesh), "--landmarks", str(f), "--out", str(out), "--no-image"], f, (out,))


# ------------------------------------------------------------------------------ more inputs
# (fit's captures, a saved identity, a voice, the take library)

def good_landmark_csv(d: Path) -> bytes:
    """Six frames of the procedural face's landmarks, the jaw dropping a little."""
    import sim.face

    model = sim.face.default_model(0)
    names = sorted(model.mesh.landmarks)[:12]
    rest = model.rest[[model.mesh.landmarks[n] for n in names]]
    rows = ["time," + ",".join(f"{n}_{c}" for n in names for c in "xyz")]
    for k in range(6):
        pts = rest.copy()
        pts[:, 1] -= 0.02 * k * (pts[:, 1] < rest[:, 1].mean())
        rows.append(f"{k / 30:.6f}," + ",".join(f"{x:.6g}" for x in pts.ravel()))
    return ("\n".join(rows) + "\n").encode()


def good_arkit_csv(d: Path) -> bytes:
    from puppet.export.arkit import ArkitCsvWriter
    from puppet.live import load_face

    face = load_face(None, 0, face="procedural")
    names = [c.name for c in face.vocab.channels]
    p = d / "good.arkit.csv"
    w = ArkitCsvWriter(p, names, 60.0)
    vals = list(face.vocab.defaults())
    for k in range(8):
        vals[names.index("jaw")] = 0.05 * k
        w.add(k, vals)
    w.close()
    return p.read_bytes()


def good_identity(d: Path) -> bytes:
    return json.dumps({"format": "facepuppet-identity", "version": 1, "name": "bob", "seed": 7,
                       "identity": [round(0.1 * ((i * 7) % 13 - 6), 3) for i in range(100)]}, indent=1).encode()


def good_wav(d: Path) -> bytes:
    import wave

    import numpy as np

    t = np.arange(4000) / 16000.0
    x = (0.3 * np.sin(2 * np.pi * 180 * t) * np.minimum(1, t * 20) * 32767).astype("<i2")
    p = d / "good.wav"
    with wave.open(str(p), "wb") as w:
        w.setnchannels(1)
        w.setsampwidth(2)
        w.setframerate(16000)
        w.writeframes(x.tobytes())
    return p.read_bytes()


def good_voice_profile(d: Path) -> bytes:
    return (Path(__file__).parents[2] / "devices" / "audio" / "profiles" / "default.json").read_bytes()


def good_library(d: Path) -> bytes:
    """A take library holding one take (registered by `puppet takes import`)."""
    folder = d / "lib-takes"
    folder.mkdir(exist_ok=True)
    (folder / "take.jsonl").write_bytes(good_recording(d))
    db = d / "good.db"
    r = run_cli(["takes", "--library", str(db), "import", str(folder)], db)
    assert r.kind == "ok", r.text
    return db.read_bytes()


def good_journal(d: Path) -> bytes:
    """A take library's journal (`takes.db.journal`): a recording begun and completed as a take,
    a second take imported, a tag and a note, as `puppet live --record` and `puppet takes` write it."""
    folder = d / "journal-takes"
    folder.mkdir(exist_ok=True)
    rec = good_recording(d)
    (folder / "a.jsonl").write_bytes(rec)
    (folder / "b.jsonl").write_bytes(rec.replace(b'"tick_rate":60.0', b'"tick_rate":50.0', 1))
    db = d / "journal-good.db"
    for argv in (["import", str(folder)], ["tag", "1", "hero"], ["note", "2", "the second try"]):
        r = run_cli(["takes", "--library", str(db), *argv], db)
        assert r.kind == "ok", r.text
    lines = db.with_name(db.name + ".journal").read_bytes().splitlines(keepends=True)
    begun = json.dumps({"op": "recording", "path": str(folder / "a.jsonl"), "tags": ["live", "dial"],
                        "performer": "ana"}).encode() + b"\n"
    return begun + b"".join(lines)


def read_journal(f: Path, d: Path) -> Outcome:
    """`puppet takes list` on a library whose database is gone and whose journal is damaged: the
    library is rebuilt from what the journal still says (a result), or one line."""
    db = d / "journal.db"
    for p in d.glob("journal.db*"):
        p.unlink()
    db.with_name(db.name + ".journal").write_bytes(f.read_bytes())
    return run_cli(["takes", "--library", str(db), "list"], f, also=db.name)


def good_midi_profile(d: Path) -> bytes:
    return (Path(__file__).parents[2] / "devices" / "midi" / "profiles" / "nanokontrol2.toml").read_bytes()


def read_midi_profile(f: Path, d: Path) -> Outcome:
    """`puppet monitor rawmidi://...?profile=FILE`: the profile is read and checked as the box opens
    (/dev/null: a port that sends nothing)."""
    return run_cli(["monitor", f"rawmidi:///dev/null?profile={f}", "--duration", "0"], f)


def good_pc2(d: Path) -> bytes:
    """Three samples of the good recording as a PC2 cache, its OBJ kept as pc2-rest.obj."""
    take = d / "pc2-take.jsonl"
    take.write_bytes(good_recording(d))
    out = d / "good.pc2"
    r = run_cli(["replay", str(take), "--to", "0.05", "--out", str(out)], take)
    assert r.kind == "ok", r.text
    (d / "good.obj").rename(d / "pc2-rest.obj")
    return out.read_bytes()


def read_pc2(f: Path, d: Path) -> Outcome:
    """`puppet fit X.pc2` (the OBJ beside it is the good one)."""
    import shutil

    shutil.copyfile(d / "pc2-rest.obj", f.with_suffix(".obj"))
    out = d / "pc2.jsonl"
    try:
        return run_cli(["fit", str(f), "--face", "procedural", "--out", str(out)], f, (out,))
    finally:
        f.with_suffix(".obj").unlink()


def good_c3d(d: Path) -> bytes:
    """Six frames of twelve landmarks of the procedural face as C3D markers."""
    import io as _io

    import c3d
    import numpy as np

    import sim.face

    model = sim.face.default_model(0)
    names = sorted(model.mesh.landmarks)[:12]
    rest = model.rest[[model.mesh.landmarks[n] for n in names]]
    w = c3d.Writer(point_rate=30.0)
    frames = []
    for k in range(6):
        p = np.zeros((len(names), 5), np.float32)
        p[:, :3] = rest * 10
        p[:, 1] -= 0.2 * k
        frames.append((p, np.zeros((0, 0), np.float32)))
    w.add_frames(frames)
    w.set_point_labels(names)
    buf = _io.BytesIO()
    w.write(buf)
    return buf.getvalue()


def good_correspondence(d: Path) -> bytes:
    """A `--map` file naming the twelve points of the landmark CSV p0..p11 as rig landmarks."""
    header = good_landmark_csv(d).split(b"\n", 1)[0].decode().split(",")[1:]
    names = [h[:-2] for h in header[::3]]
    return json.dumps({"points": {f"p{i}": n for i, n in enumerate(names)}}, indent=1).encode()


def read_correspondence(f: Path, d: Path) -> Outcome:
    """`puppet fit points.csv --map FILE` with the landmark CSV's points renamed p0..p11."""
    cap = d / "points.csv"
    if not cap.exists():
        lines = good_landmark_csv(d).decode().split("\n")
        cols = lines[0].split(",")
        cols = ["time"] + [f"p{(i - 1) // 3}_{c[-1]}" for i, c in enumerate(cols) if i]
        cap.write_text("\n".join([",".join(cols), *lines[1:]]))
    out = d / "mapped.jsonl"
    return run_cli(["fit", str(cap), "--face", "procedural", "--map", str(f), "--out", str(out)], f, (out,))


def read_landmark_csv(f: Path, d: Path) -> Outcome:
    out = d / "fit.jsonl"
    return run_cli(["fit", str(f), "--face", "procedural", "--out", str(out)], f, (out,))


def read_identity(f: Path, d: Path) -> Outcome:
    """`--face NAME` of a saved identity, as `puppet face list` and every command read it."""
    import os

    saved = d / "identities"
    saved.mkdir(exist_ok=True)
    (saved / "bob.json").write_bytes(f.read_bytes())
    old = os.environ.get("PUPPET_DATA_DIR")
    os.environ["PUPPET_DATA_DIR"] = str(saved)
    try:
        r = run_cli(["face", "list"], saved / "bob.json", also="bob.json")
        if r.kind != "traceback":
            from puppet.faces import load_identity

            try:
                load_identity("bob")
            except Exception as err:  # noqa: BLE001 - what a --face bob would print
                from puppet.errors import PuppetError

                line = str(err)
                if not isinstance(err, PuppetError) or "\n" in line or len(line) > MAX_LINE or "bob.json" not in line:
                    return Outcome("traceback", f"--face bob: {type(err).__name__}: {line[:300]}")
        return r
    finally:
        if old is None:
            del os.environ["PUPPET_DATA_DIR"]
        else:
            os.environ["PUPPET_DATA_DIR"] = old


def read_wav(f: Path, d: Path) -> Outcome:
    out = d / "voice.jsonl"
    return run_cli(["fit", str(f), "--face", "procedural", "--out", str(out)], f, (out,))


def read_voice_profile(f: Path, d: Path) -> Outcome:
    wav = d / "speech.wav"
    if not wav.exists():
        good_wav(d)
        (d / "good.wav").rename(wav)
    out = d / "voice.jsonl"
    return run_cli(["fit", str(wav), "--face", "procedural", "--voice-profile", str(f), "--out", str(out)], f,
                   (out,))


def read_library(f: Path, d: Path) -> Outcome:
    """`puppet takes list` on a damaged library: a result (the library rebuilt, with a warning) or
    one line. The damaged file is kept beside it, never lost (an empty one holds nothing to keep)."""
    before = f.read_bytes()
    r = run_cli(["takes", "--library", str(f), "list"], f)
    kept = [p for p in f.parent.glob(f.name + ".damaged-*")]
    lost = before and not (f.exists() and f.read_bytes() == before) and not any(p.read_bytes() == before for p in kept)
    if lost:
        return Outcome("traceback", f"the damaged library was not kept: {r.text[-300:]}")
    for p in kept:
        p.unlink()
    return r


def _wav_extra(rng: object) -> Iterator[damage.Variant]:
    import struct

    good = good_wav(Path(tempfile.mkdtemp(prefix="wav-")))
    yield "channels-0", good[:22] + struct.pack("<H", 0) + good[24:]
    yield "channels-huge", good[:22] + struct.pack("<H", 65535) + good[24:]
    yield "rate-0", good[:24] + struct.pack("<I", 0) + good[28:]
    yield "rate-huge", good[:24] + struct.pack("<I", 2**32 - 1) + good[28:]
    yield "bits-7", good[:34] + struct.pack("<H", 7) + good[36:]
    yield "data-4GB", good[:40] + struct.pack("<I", 2**32 - 1) + good[44:]
    yield "fmt-huge", good[:16] + struct.pack("<I", 2**32 - 1) + good[20:]
    yield "no-fmt", good[:12] + good[36:]
    yield "riff-only", good[:12]
    yield "not-wave", good[:8] + b"AVI " + good[12:]


def _ply_extra(rng: object) -> Iterator[damage.Variant]:
    good = good_ply_bin(Path("."))
    head, _, body = good.partition(b"end_header\n")
    yield "count-huge", head.replace(b"element vertex 120", b"element vertex 99999999999") + b"end_header\n" + body
    yield "count-neg", head.replace(b"element vertex 120", b"element vertex -5") + b"end_header\n" + body
    yield "face-huge", head.replace(b"element face 150", b"element face 4000000000") + b"end_header\n" + body
    yield "no-y", head.replace(b"property float y", b"property float q") + b"end_header\n" + body


def _stl_extra(rng: object) -> Iterator[damage.Variant]:
    good = good_stl(Path("."))
    yield "count-huge", good[:80] + (2**32 - 1).to_bytes(4, "little") + good[84:]
    yield "count-zero", good[:80] + b"\0\0\0\0" + good[84:]
    yield "ascii-cut", b"solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0 nan\n"
    yield "ascii-good", (b"solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\n"
                         b"endloop\nendfacet\nendsolid x\n")
    yield "latin1", b"solid \xff\xfe\n" + good[10:]


FORMATS: tuple[Format, ...] = (
    Format("recording", ".jsonl", good_recording, lambda g: damage.recording_variants(g, n=320), read_recording),
    Format("recording-headless", ".jsonl", good_recording,
           lambda g: damage.recording_variants(g, seed=15, n=150), read_recording_headless),
    Format("mapping", ".toml", good_mapping, lambda g: damage.toml_variants(g, n=300), read_mapping),
    Format("curves", ".curves", good_curves, lambda g: damage.text_variants(g, n=240), read_curves),
    Format("curves-v2", ".curves", good_curves_v2, lambda g: damage.text_variants(g, seed=21, n=240), read_curves),
    Format("rig", ".npz", good_rig, lambda g: damage.rig_variants(g, n=180), read_rig),
    Format("mock-toml", ".toml", good_mock_toml, lambda g: damage.toml_variants(g, n=240), read_mock),
    Format("mock-json", ".json", good_mock_json, lambda g: damage.json_variants(g, n=200), read_mock),
    Format("dbc", ".dbc", good_dbc, lambda g: damage.text_variants(g, n=120), read_dbc),
    Format("obj", ".obj", good_obj, lambda g: damage.text_variants(g, n=200), read_mesh),
    Format("ply", ".ply", good_ply, lambda g: damage.text_variants(g, n=150), read_mesh),
    Format("ply-binary", ".ply", good_ply_bin, lambda g: damage.binary_variants(g, n=120, extra=_ply_extra),
           read_mesh),
    Format("stl", ".stl", good_stl, lambda g: damage.binary_variants(g, n=120, extra=_stl_extra), read_mesh),
    Format("off", ".off", good_off, lambda g: damage.text_variants(g, n=120), read_mesh),
    Format("glb", ".glb", good_glb, lambda g: damage.binary_variants(g, n=120), read_mesh),
    Format("landmarks", ".json", good_landmarks, lambda g: damage.json_variants(g, n=150), read_landmarks),
    Format("landmark-csv", ".csv", good_landmark_csv, lambda g: damage.text_variants(g, n=150), read_landmark_csv),
    Format("arkit-csv", ".csv", good_arkit_csv, lambda g: damage.text_variants(g, n=150), read_landmark_csv),
    Format("correspondence", ".json", good_correspondence, lambda g: damage.json_variants(g, n=150),
           read_correspondence),
    Format("c3d", ".c3d", good_c3d, lambda g: damage.binary_variants(g, n=150), read_landmark_csv),
    Format("pc2", ".pc2", good_pc2, lambda g: damage.binary_variants(g, n=120), read_pc2),
    Format("identity", ".json", good_identity, lambda g: damage.json_variants(g, n=150), read_identity),
    Format("wav", ".wav", good_wav, lambda g: damage.binary_variants(g, n=120, extra=_wav_extra), read_wav,
           refused=0.1),
    Format("voice-profile", ".json", good_voice_profile, lambda g: damage.json_variants(g, n=150),
           read_voice_profile),
    Format("library", ".db", good_library, lambda g: damage.binary_variants(g, n=130), read_library),
    Format("midi-profile", ".toml", good_midi_profile, lambda g: damage.toml_variants(g, n=240), read_midi_profile),
    Format("library-journal", ".journal", good_journal, lambda g: damage.jsonl_variants(g, n=160), read_journal,
           refused=0.0),  # the journal is read as far as it can be: every variant rebuilds a library
)


def run_format(fmt: Format, d: Path, limit: int | None = None) -> dict[str, list[tuple[str, str]]]:
    """Every variant of `fmt` through its reader: {kind: [(variant, text)]}."""
    d.mkdir(parents=True, exist_ok=True)
    good = fmt.good(d)
    seen: dict[str, list[tuple[str, str]]] = {"ok": [], "error": [], "traceback": []}
    for i, (name, data) in enumerate(fmt.variants(good)):
        if limit is not None and i >= limit:
            break
        f = d / f"v{i:04d}{fmt.suffix}"
        f.write_bytes(data)
        r = fmt.read(f, d)
        seen[r.kind].append((name, r.text))
        f.unlink()
    return seen
