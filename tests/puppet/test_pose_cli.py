"""The `puppet pose` and `puppet channels` contract: outputs, option handling and exit-2 errors."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from puppet.cli import main


def _cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "puppet", *args], capture_output=True, text=True)


def test_pose_npz_has_the_contract_arrays_and_the_smile_moves_the_corners(tmp_path: Path) -> None:
    out = tmp_path / "smile.npz"
    assert main(["pose", "--expression", "happiness", "--seconds", "0.5", "--out", str(out)]) == 0
    with np.load(out, allow_pickle=False) as d:
        rest, pos, tris = d["rest"], d["positions"], d["triangles"]
        names, idx = list(d["landmark_names"]), d["landmark_indices"]
    n = len(rest)
    assert pos.shape == (n, 3) and tris.shape[1] == 3 and tris.max() < n
    assert len(names) == len(idx) > 10
    corner = idx[names.index("mouth_corner_l")]
    assert pos[corner, 1] - rest[corner, 1] > 0.2  # up by more than 2 mm


def test_pose_settles_by_default_and_combines_options(tmp_path: Path) -> None:
    out = tmp_path / "p.npz"
    res = _cli("pose", "--set", "jaw=0.5", "--au", "AU12_L=0.8", "--expression", "surprise=0.5",
               "--age", "60", "--out", str(out))
    assert res.returncode == 0, res.stderr
    assert "wrote" in res.stdout
    with np.load(out) as d:
        names = list(d["landmark_names"])
        chin = d["landmark_indices"][names.index("chin")]
        assert d["positions"][chin, 1] < d["rest"][chin, 1] - 1.0  # the jaw is open


def test_pose_obj(tmp_path: Path) -> None:
    out = tmp_path / "p.obj"
    assert main(["pose", "--seconds", "0.1", "--out", str(out)]) == 0
    lines = out.read_text().splitlines()
    assert sum(1 for ln in lines if ln.startswith("v ")) > 500
    assert sum(1 for ln in lines if ln.startswith("f ")) > 1000


def test_pose_obj_of_a_turned_head_is_turned_as_drawn(tmp_path: Path) -> None:
    """The head turns on the neck (head_yaw), drawn and in a PC2 turned; the procedural face's OBJ
    held the skin in the head's own frame, facing front. At head_yaw 0.5 (45 degrees) the nose tip
    swings sideways by centimetres while the face keeps its shape (a turn, not a deformation)."""
    def verts(path: Path) -> np.ndarray:
        return np.array([[float(x) for x in ln.split()[1:4]] for ln in path.read_text().splitlines()
                         if ln.startswith("v ")])

    rest, turned = tmp_path / "rest.obj", tmp_path / "turned.obj"
    for out, extra in ((rest, []), (turned, ["--set", "head_yaw=0.5"])):
        assert main(["pose", "--face", "procedural", "--seconds", "0.05", *extra, "--out", str(out)]) == 0
    a, b = verts(rest), verts(turned)
    nose = int(np.argmax(a[:, 2]))
    assert abs(b[nose, 0] - a[nose, 0]) > 3.0  # cm
    top = np.flatnonzero(a[:, 1] > np.median(a[:, 1]))[::7]
    def dist(p: np.ndarray) -> np.ndarray:
        return np.linalg.norm(p[top][:, None] - p[top][None], axis=2)
    assert np.abs(dist(b) - dist(a)).max() < 0.05


@pytest.mark.parametrize(
    "args, needle",
    [
        (["--set", "nosuch=1"], "`puppet channels` lists every one"),  # where the valid names are
        (["--set", "zygomatic_major_l=1"], "nearest: zygomaticus_major_l"),  # the nearest valid names
        (["--set", "jaw=1.5"], "0..1"),
        (["--set", "jaw"], "CHANNEL=VALUE"),
        (["--set", "jaw=abc"], "number"),
        (["--au", "AU99=1"], "nearest: AU9"),
        (["--au", "AU12=2"], "0..1"),
        (["--expression", "joy"], "happiness"),
        (["--expression", "anger=3"], "0..1"),
        (["--age", "500"], "0..120"),
    ],
)
def test_bad_channel_au_expression_or_value_is_one_line_exit_2(
    tmp_path: Path, args: list[str], needle: str
) -> None:
    out = tmp_path / "x.npz"
    res = _cli("pose", *args, "--out", str(out))
    assert res.returncode == 2
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("puppet: error:") and needle in lines[0]
    assert len(lines[0]) <= 300  # a short line, not every valid name
    assert not out.exists()


def test_malformed_rig_file_is_one_line_exit_2(tmp_path: Path) -> None:
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not a zip at all")
    res = _cli("pose", "--rig", str(bad), "--out", str(tmp_path / "x.npz"))
    assert res.returncode == 2
    assert res.stderr.count("\n") == 1 and str(bad) in res.stderr


def test_unknown_output_type_is_an_error(tmp_path: Path) -> None:
    res = _cli("pose", "--out", str(tmp_path / "x.stl"))
    assert res.returncode == 2 and ".npz" in res.stderr


def test_channels_json_lists_every_channel() -> None:
    res = _cli("channels", "--json")
    assert res.returncode == 0
    rows = json.loads(res.stdout)
    names = [r["name"] for r in rows]
    for must in ("zygomaticus_major_l", "orbicularis_oris", "jaw", "eyes_yaw", "eyes_pitch", "age",
                 "procerus", "mentalis", "orbicularis_oculi_lid_r"):
        assert must in names
    oris = rows[names.index("orbicularis_oris")]
    assert oris["muscle_type"] == "sphincter" and "AU23" in oris["aus"] and oris["kind"] == "muscle"
    age = rows[names.index("age")]
    assert age["default"] == 30 and age["hi"] >= 100
    assert all({"name", "kind", "aus", "lo", "hi", "default", "muscle_type"} <= set(r) for r in rows)


def test_channels_table(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["channels"]) == 0
    text = capsys.readouterr().out
    assert "zygomaticus_major_l" in text and "sphincter" in text and "AU12" in text


@pytest.mark.parametrize("argv", [["pose", "--seconds", "0", "--size", "99999x99999"],
                                  ["replay", "--curves", "CURVES", "--size", "40000x16"],
                                  ["replay", "--curves", "CURVES", "--size", "8000x16", "--supersample", "4"]])
def test_an_image_size_beyond_what_can_be_drawn_is_one_line(argv: list[str], tmp_path: Path,
                                                           capsys: pytest.CaptureFixture[str]) -> None:
    """`--size 99999x99999` ended `puppet pose` in moderngl's traceback (the framebuffer cannot be
    made), `puppet replay` in a line about the OpenGL context, and 8000 pixels supersampled 4
    times in a traceback; each says the limit now, exit 2, and writes nothing."""
    curves = tmp_path / "k.curves"
    curves.write_text("facepuppet-curves 1\ncurve jaw linear replace\n 0 0\n 0.1 0.5\nend\n")
    out = tmp_path / "big.png"
    argv = [str(curves) if a == "CURVES" else a for a in argv]
    try:
        code = main([*argv, "--out", str(out)])
    except SystemExit as e:  # argparse's own line
        code = e.code
    err = capsys.readouterr().err.strip()
    assert code == 2 and "Traceback" not in err, err
    lines = err.splitlines()
    assert ("8192" in lines[-1] or "16384" in lines[-1]) and "--size" in lines[-1], err
    assert not out.exists()


def test_an_unknown_view_for_a_picture_is_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """`puppet pose --view bogus --out p.png` was a ValueError traceback once the face had settled."""
    out = tmp_path / "p.png"
    assert main(["pose", "--seconds", "0", "--view", "bogus", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--view 'bogus'" in err and "shaded" in err
    assert not out.exists()


def test_options_that_name_another_face_are_refused_not_ignored(tmp_path: Path,
                                                                 capsys: pytest.CaptureFixture[str]) -> None:
    """`--rig R --face ict` ran the rig and `--face ict --resolution 2` the scanned head, each
    option dropped without a word. One line naming both options, exit 2, nothing written (the
    checks come before the face loads)."""
    out = tmp_path / "p.png"
    rig = tmp_path / "r.npz"
    rig.write_bytes(b"never read")
    for argv, words in ((["pose", "--rig", str(rig), "--face", "ict"], ("--rig", "--face")),
                        (["view", "--rig", str(rig), "--face", "procedural"], ("--rig", "--face")),
                        (["fit", "x.csv", "--rig", str(rig), "--face", "ict"], ("--rig", "--face")),
                        (["pose", "--face", "ict", "--resolution", "2"], ("--resolution", "ict")),
                        (["pose", "--rig", str(rig), "--resolution", "1"], ("--resolution",))):
        assert main([*argv, "--out", str(out)]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and all(w in err for w in words), err
        assert not out.exists()


def test_image_options_on_a_mesh_pose_are_said_not_to_apply(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """`pose --out smile.npz --view wireframe --size 640x480` dropped both without a word; now one line
    names them, and the pose written is the one written without them."""
    plain, given = tmp_path / "plain.npz", tmp_path / "given.npz"
    base = ["pose", "--face", "procedural", "--au", "AU12=0.6", "--seconds", "0.1"]
    assert main([*base, "--out", str(plain)]) == 0
    assert "note" not in capsys.readouterr().err
    assert main([*base, "--out", str(given), "--view", "wireframe", "--size", "640x480"]) == 0
    err = [line for line in capsys.readouterr().err.splitlines() if "note" in line]
    assert err == ["puppet: note: --size and --view do not apply to .npz (only images are drawn); ignored"], err
    with np.load(plain) as a, np.load(given) as b:
        assert set(a.files) == set(b.files) and all(np.array_equal(a[k], b[k]) for k in a.files)
