"""Keyframe curves: parse, evaluate, layer over values, export from a performance and back."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from puppet.curves import CurveLayer, curves_from_values, parse_curves
from puppet.errors import ConfigError
from puppet_helpers import CHANNELS, idx, vocab

TEXT = """facepuppet-curves 1
# a smile that comes and goes
curve zygomaticus_major smooth
  0.0  0
  1.0  1.0
  2.0  0
end
curve jaw step add
  0.5 0.25
  1.5 0.5
end
"""


def test_evaluate_interpolations_and_span() -> None:
    cs = parse_curves(TEXT)
    smile, jaw = cs.curves
    assert smile.at(0.5) == pytest.approx(0.5) and smile.at(0.25) == pytest.approx(0.15625)
    assert jaw.at(1.0) == 0.25 and jaw.at(0.4) is None and smile.at(2.5) is None
    assert cs.duration == 2.0


def test_layer_replace_and_add() -> None:
    layer = CurveLayer(parse_curves(TEXT), vocab())
    base = np.array([c.default for c in CHANNELS])
    base[idx("jaw")] = 0.6
    out = layer.apply(base, 1.0)
    assert out[idx("zygomaticus_major_l")] == out[idx("zygomaticus_major_r")] == 1.0
    assert out[idx("jaw")] == pytest.approx(0.85)
    assert layer.apply(base, 3.0)[idx("jaw")] == 0.6  # outside every span: untouched


@pytest.mark.parametrize(
    "text,line,what",
    [
        ("hello", 1, "facepuppet-curves 1"),
        ("facepuppet-curves 1\ncurve jaw\n0 x\nend\n", 3, "two numbers"),
        ("facepuppet-curves 1\ncurve jaw bouncy\n", 2, "unknown word"),
        ("facepuppet-curves 1\ncurve jaw\n1 0\n0.5 1\nend\n", 4, "back in time"),
        ("facepuppet-curves 1\ncurve jaw\n1 0\n", 2, "not closed"),
    ],
)
def test_errors_name_the_line(text: str, line: int, what: str) -> None:
    with pytest.raises(ConfigError, match=rf"^c.txt:{line}: .*{what}"):
        parse_curves(text, "c.txt")


def test_unknown_target_names_its_line() -> None:
    with pytest.raises(ConfigError, match=r"^c:2: unknown target 'smirk'"):
        CurveLayer(parse_curves("facepuppet-curves 1\ncurve smirk\n0 1\nend\n", "c"), vocab())


def test_export_then_play_back_reproduces_the_performance() -> None:
    rate = 60.0
    t = np.arange(240) / rate
    vals = np.tile(np.array([c.default for c in CHANNELS]), (len(t), 1))
    smile = np.clip(np.sin(t * 2), 0, 1)
    vals[:, idx("zygomaticus_major_l")] = smile
    vals[:, idx("zygomaticus_major_r")] = smile
    vals[:, idx("age")] = 30 + 10 * (t > 2)
    names = [c.name for c in CHANNELS]
    text = curves_from_values(vals, names, rate, vocab(), tolerance=0.002)
    assert "curve zygomaticus_major " in text and "curve zygomaticus_major_r" not in text
    assert "curve jaw" not in text  # channels that never move are left out
    cs = parse_curves(text)
    assert sum(len(c.times) for c in cs.curves) < len(t) // 4  # reduced to few keys
    layer = CurveLayer(cs, vocab())
    base = np.array([c.default for c in CHANNELS])
    back = np.array([layer.apply(base, k / rate) for k in range(len(t))])
    assert np.abs(back[:, idx("zygomaticus_major_l")] - smile).max() < 0.01
    assert back[-1, idx("age")] == 40.0 and back[0, idx("age")] == 30.0


def test_an_export_over_its_own_curves_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """`puppet replay --curves keys.curves --out keys.curves` baked the hand-set keys into a key
    per tick over the very file being read; refused in one line, the keys kept byte for byte."""
    from puppet.cli import main

    keys = tmp_path / "keys.curves"
    keys.write_text("facepuppet-curves 1\n# hand-set\ncurve jaw smooth replace\n  0.0 0\n  0.5 0.6\nend\n")
    before = keys.read_bytes()
    assert main(["replay", "--curves", str(keys), "--out", str(tmp_path / "." / "keys.curves")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "keys.curves" in err and "--out" in err, err
    assert keys.read_bytes() == before
