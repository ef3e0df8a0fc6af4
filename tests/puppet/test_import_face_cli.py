"""`puppet import-face` end to end in a subprocess: OBJ + landmark JSON in, rig + report +
picture out; bad inputs give one `puppet: error:` line naming the file and exit status 2."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation


def _puppet(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "puppet", *args], capture_output=True, text=True,
                          cwd=cwd, timeout=120)


@pytest.fixture(scope="module")
def head(tmp_path_factory) -> tuple[Path, dict, np.ndarray]:
    """The default face re-meshed, in millimetres, lying on its side, written as OBJ."""
    import trimesh

    from sim.face.builder import build_face_mesh

    mesh = build_face_mesh(0)
    rot = Rotation.from_euler("zyx", [90, 25, -10], degrees=True).as_matrix()
    verts = 10.0 * mesh.vertices @ rot.T + [120.0, 5.0, -30.0]
    d = tmp_path_factory.mktemp("head")
    trimesh.Trimesh(verts, mesh.triangles, process=False).export(d / "head.obj")
    return d, {k: int(v) for k, v in mesh.landmarks.items()}, verts


def test_import_face_writes_rig_report_and_picture(head) -> None:
    from PIL import Image

    from sim.build import compile_model
    from sim.rig import load_rig

    d, lms, verts = head
    # half the landmarks as vertex indices, half as points: both forms are accepted
    data = {k: (v if i % 2 else verts[v].tolist()) for i, (k, v) in enumerate(sorted(lms.items()))}
    (d / "landmarks.json").write_text(json.dumps({"landmarks": data}))
    out = _puppet("import-face", "head.obj", "--landmarks", "landmarks.json", "--out", "head.npz", cwd=d)
    assert out.returncode == 0, out.stderr
    assert "wrote head.npz" in out.stdout
    rig = load_rig(d / "head.npz")
    assert rig.name == "head" and len(rig.muscles) > 20
    top, chin = rig.mesh.landmark("forehead_center"), rig.mesh.landmark("chin")
    assert top[1] - chin[1] > 10  # cm and upright, although the file was mm and on its side
    compile_model(rig)
    report = (d / "head.report.md").read_text()
    assert "scale to cm: x0.1" in report and "muscles transferred: " in report
    assert "| nose_tip |" in report
    img = np.asarray(Image.open(d / "head.png").convert("RGB")).astype(int)
    red = (img[..., 0] > 150) & (img[..., 1] < 80) & (img[..., 2] < 80)
    assert red.sum() > 500  # the muscles are drawn over the face


def _error_line(out: subprocess.CompletedProcess) -> str:
    assert out.returncode == 2, (out.stdout, out.stderr)
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("puppet: error: "), out.stderr
    return lines[0]


def test_missing_landmark_is_one_clear_line(head) -> None:
    d, lms, _ = head
    (d / "partial.json").write_text(json.dumps({k: v for k, v in lms.items() if k != "subnasale"}))
    line = _error_line(_puppet("import-face", "head.obj", "--landmarks", "partial.json", "--out",
                               "x.npz", cwd=d))
    assert "partial.json: missing landmark(s) subnasale" in line
    assert not (d / "x.npz").exists()


def test_bad_inputs_are_one_clear_line(head) -> None:
    d, lms, verts = head
    far = dict(lms)
    far["nose_tip"] = (verts[lms["nose_tip"]] + [0.0, 0.0, 500.0]).tolist()
    (d / "far.json").write_text(json.dumps(far))
    line = _error_line(_puppet("import-face", "head.obj", "--landmarks", "far.json", "--out", "x.npz", cwd=d))
    assert "far.json: landmark 'nose_tip' lies" in line and "head.obj" in line
    (d / "blob.ply").write_text("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n"
                                "property float y\nproperty float z\nend_header\n0 0 0\n1 0 0\n0 1 0\n")
    line = _error_line(_puppet("import-face", "blob.ply", "--landmarks", "far.json", "--out", "x.npz", cwd=d))
    assert "blob.ply" in line


def test_transfer_from_a_rig_file_without_picture(head, capsys) -> None:
    """--rig picks the rig to transfer from (here a saved built-in face); --no-image skips the
    picture. Run in-process through the same dispatcher."""
    from puppet.cli import main
    from sim.face import default_rig
    from sim.rig import load_rig, save_rig

    d, lms, _ = head
    ref = default_rig(0)
    ref.name = "my-reference"
    save_rig(ref, d / "ref.npz")
    (d / "idx.json").write_text(json.dumps(lms))
    code = main(["import-face", str(d / "head.obj"), "--landmarks", str(d / "idx.json"), "--out",
                 str(d / "from_ref.npz"), "--rig", str(d / "ref.npz"), "--no-image", "--name", "mine"])
    assert code == 0, capsys.readouterr().err
    rig = load_rig(d / "from_ref.npz")
    assert rig.name == "mine" and set(rig.muscles) == set(ref.muscles)
    assert not (d / "from_ref.png").exists() and (d / "from_ref.report.md").exists()
    (d / "broken.npz").write_bytes(b"not a rig")
    code = main(["import-face", str(d / "head.obj"), "--landmarks", str(d / "idx.json"), "--out",
                 str(d / "x.npz"), "--rig", str(d / "broken.npz")])
    assert code == 2 and "broken.npz" in capsys.readouterr().err


def test_rest_eyes_seats_the_eyeballs_behind_the_lids(head, capsys) -> None:
    """--rest-eyes moves each eyeball to sit behind the head's own lids (sim.face.transfer.eyes);
    without it the eyeballs stay where the skin correspondence carried them."""
    from puppet.cli import main
    from sim.rig import load_rig

    d, lms, _ = head
    (d / "idx.json").write_text(json.dumps(lms))
    centres = {}
    for flag in ((), ("--rest-eyes",)):
        out = d / f"eyes{len(flag)}.npz"
        code = main(["import-face", str(d / "head.obj"), "--landmarks", str(d / "idx.json"), "--out", str(out),
                     "--no-image", *flag])
        assert code == 0, capsys.readouterr().err
        centres[flag] = np.asarray(load_rig(out).mesh.eye_centers)
    assert np.abs(centres[("--rest-eyes",)] - centres[()]).max() > 0.01  # cm: the eyeballs moved


def test_a_texture_named_like_the_rig_is_kept(head, tmp_path: Path, capsys) -> None:
    """head.obj with its texture head.png beside it, imported to head.npz: the muscles picture
    (RIG.png) used to replace the texture. The texture is kept, with a warning, every time; a
    picture an earlier import drew is still replaced."""
    from puppet.cli import main

    d, lms, verts = head
    (tmp_path / "head.obj").write_bytes((d / "head.obj").read_bytes())
    (tmp_path / "idx.json").write_text(json.dumps({"landmarks": lms}))
    texture = tmp_path / "head.png"
    texture.write_bytes(b"\x89PNG the user's texture")
    argv = ["import-face", str(tmp_path / "head.obj"), "--landmarks", str(tmp_path / "idx.json"), "--out",
            str(tmp_path / "head.npz")]
    for _ in range(2):
        assert main(argv) == 0
        assert texture.read_bytes() == b"\x89PNG the user's texture"
        assert "head.png" in capsys.readouterr().err
    texture.unlink()
    assert main(argv) == 0 and texture.read_bytes().startswith(b"\x89PNG\r\n")
    drawn = texture.stat().st_mtime_ns
    assert main(argv) == 0 and texture.stat().st_mtime_ns != drawn  # its own picture: drawn again
