"""Every format the program reads, damaged hundreds of ways (fixed seed), through the real
commands: each variant gives a result or one short `puppet: error:` line naming the file, exit 2,
and a failed export leaves the user's old --out file byte for byte. Never a traceback."""

from __future__ import annotations

import subprocess
import sys
import warnings
from pathlib import Path

import pytest

import damage
import formats

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize("fmt", formats.FORMATS, ids=[f.name for f in formats.FORMATS])
def test_damaged_variants_give_a_result_or_one_line(fmt: formats.Format, tmp_path: Path) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        seen = formats.run_format(fmt, tmp_path)
    n = sum(len(v) for v in seen.values())
    assert n >= 80, f"only {n} variants of {fmt.name}"
    bad = seen["traceback"]
    assert not bad, f"{len(bad)} of {n} {fmt.name} variants: " + "; ".join(f"{k}: {t[-300:]}" for k, t in bad[:3])
    assert len(seen["error"]) >= n * fmt.refused  # the variants are damaged: many must be refused


def _puppet(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "puppet", *args], capture_output=True, text=True, cwd=cwd,
                          timeout=120)


def _one_line(r: subprocess.CompletedProcess, name: str) -> str:
    assert r.returncode == 2, r.stderr
    assert "Traceback" not in r.stderr
    lines = [ln for ln in r.stderr.splitlines() if ln.startswith("puppet: error:")]
    assert len(lines) == 1 and name in lines[0] and len(lines[0]) < formats.MAX_LINE, r.stderr
    return lines[0]


def test_a_sample_through_the_command_in_a_process(tmp_path: Path) -> None:
    """A sample of the damage, from outside: the recording killed after its header, a tick rate of
    0, a landmark file nested thousands deep, a damaged STL, a mesh that collapses to a point, a
    mapping integer of 400 digits, a mock script nested thousands deep."""
    good = formats.good_recording(tmp_path)
    header = good.splitlines()[0]
    (tmp_path / "header-only.jsonl").write_bytes(header + b"\n")
    (tmp_path / "rate0.jsonl").write_bytes(header.replace(b'"tick_rate":60.0', b'"tick_rate":0') + b"\n")
    (tmp_path / "out.mp4").write_bytes(formats.OLD)
    line = _one_line(_puppet("replay", "header-only.jsonl", "--out", "out.mp4", cwd=tmp_path), "header-only.jsonl")
    assert "holds no performance" in line
    assert (tmp_path / "out.mp4").read_bytes() == formats.OLD
    line = _one_line(_puppet("replay", "rate0.jsonl", "--out", "x.csv", cwd=tmp_path), "rate0.jsonl")
    assert "tick_rate" in line and "--fps" not in line

    (tmp_path / "deep.json").write_text("[" * 5000 + "]" * 5000)
    (tmp_path / "point.obj").write_text("v 1 1 1\n" * 4 + "f 1 2 3\nf 2 3 4\n")
    stl = formats.good_stl(tmp_path)
    (tmp_path / "cut.stl").write_bytes(stl[: len(stl) // 2])
    (tmp_path / "all.json").write_text(formats.good_landmarks(tmp_path).decode())
    (tmp_path / "head.obj").write_bytes(formats.good_obj(tmp_path))
    line = _one_line(_puppet("import-face", "head.obj", "--landmarks", "deep.json", "--out", "r.npz",
                             cwd=tmp_path), "deep.json")
    assert "nested too deep" in line
    line = _one_line(_puppet("import-face", "point.obj", "--landmarks", "all.json", "--out", "r.npz",
                             cwd=tmp_path), "point.obj")
    assert "collapses to a point" in line
    line = _one_line(_puppet("import-face", "cut.stl", "--landmarks", "all.json", "--out", "r.npz",
                             cwd=tmp_path), "cut.stl")
    assert "module" not in line and "STL" in line
    assert not (tmp_path / "r.npz").exists()

    (tmp_path / "huge.toml").write_text('version = 1\n[[binding]]\ncontrol = "dial0"\ntarget = "jaw"\ngain = '
                                        + "9" * 400 + "\n")
    line = _one_line(_puppet("live", "--map", "huge.toml", "--headless", "--duration", "0.1", "--device",
                             "mock://?sine=dial0", cwd=tmp_path), "huge.toml:5")
    assert "gain" in line
    line = _one_line(_puppet("monitor", "mock://deep.json", "--duration", "0", cwd=tmp_path), "deep.json")
    assert "nested too deep" in line


def test_generators_are_deterministic_and_cover_the_damage_kinds() -> None:
    good = b'{"a": [1, 2.5, {"b": "c"}], "d": 7}'
    one = list(damage.json_variants(good, seed=3, n=80))
    two = list(damage.json_variants(good, seed=3, n=80))
    assert one == two and len(one) >= 60
    names = " ".join(n for n, _ in one)
    for kind in ("cut@", "flip", "utf16", "empty", "deep-json", "=huge-int", "=nan", "=word"):
        assert kind in names, kind
