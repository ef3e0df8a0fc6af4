"""What a user sees for the damage the issue names: header-only takes, tick rates of 0, values
far outside a channel's range, counts that ask for terabytes, huge integers in a mapping, error
lines that quote a short prefix of a bad value."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import formats
from puppet.errors import ConfigError
from safefile import BadFile, load_json, load_toml, number, quote


def _take(tmp_path: Path, body: str, **header_changes: object) -> Path:
    good = formats.good_recording(tmp_path).decode().splitlines()
    header = json.loads(good[0])
    header.update(header_changes)
    p = tmp_path / "take.jsonl"
    p.write_text(json.dumps(header) + "\n" + body)
    return p


def test_a_header_only_take_replays_as_an_empty_take(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    from puppet.cli import main

    p = _take(tmp_path, "")
    assert main(["replay", str(p), "--headless"]) == 0
    assert "holds no performance" in capsys.readouterr().out
    out = tmp_path / "take.csv"
    out.write_bytes(formats.OLD)
    assert main(["replay", str(p), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "take.jsonl holds no performance" in err and "nothing to export" in err
    assert out.read_bytes() == formats.OLD


@pytest.mark.parametrize("rate", [0, -60, 1e308, "sixty", None, [60]])
def test_a_bad_tick_rate_names_the_recording_not_the_options(tmp_path: Path, rate: object) -> None:
    from puppet.session import read_session

    p = _take(tmp_path, '{"t":"end","ticks":3}\n', tick_rate=rate)
    with pytest.raises(ConfigError, match=r"take\.jsonl:1: tick_rate") as e:
        read_session(p)
    assert "--fps" not in str(e.value)


def test_a_channel_value_far_outside_its_range_is_clamped_with_a_warning(
        tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    from puppet.replay import Replayer, build_performance
    from puppet.session import read_session

    p = _take(tmp_path, '{"t":"v","tick":0,"v":{"jaw":1e308,"eyes_yaw":-5e9}}\n{"t":"end","ticks":20}\n')
    perf = build_performance(read_session(p), None)
    err = capsys.readouterr().err
    assert "outside their channel's range" in err and "jaw = 1e+308" in err and "clamped" in err
    names = [c.name for c in perf.face.vocab.channels]
    jaw = perf.face.vocab.channels[names.index("jaw")]
    assert perf.values[:, names.index("jaw")].max() == jaw.hi
    assert perf.values[:, names.index("eyes_yaw")].min() == perf.face.vocab.channels[names.index("eyes_yaw")].lo
    rp = Replayer(perf)
    rp.seek(20)
    moved = np.linalg.norm(rp.state.positions - perf.face.model.rest, axis=1).max()
    assert np.isfinite(moved) and moved < 5.0  # cm: a wide-open jaw, not a face thrown across the room


@pytest.mark.parametrize("record", ['{"t":"end","ticks":10000000000000}', '{"t":"sync","tick":99999999}',
                                    '{"t":"end","ticks":1e300}', '{"t":"end","ticks":-4}'])
def test_a_count_asking_for_terabytes_is_refused_or_ends_the_take(tmp_path: Path, record: str) -> None:
    from puppet.session import read_session

    p = _take(tmp_path, record + "\n")
    try:
        s = read_session(p)
    except ConfigError as err:
        assert "take.jsonl" in str(err) and len(str(err)) < 300
        return
    assert s.ticks * len(s.channels) <= 50_000_000 and s.warnings


def test_a_huge_integer_in_a_mapping_is_one_line_with_its_place(tmp_path: Path) -> None:
    from puppet.mapping import load_mapping

    p = tmp_path / "m.toml"
    p.write_text('version = 1\n[[binding]]\ncontrol = "dial0"\ntarget = "jaw"\ngain = ' + "9" * 400 + "\n")
    with pytest.raises(ConfigError, match=r"m\.toml:5:\d+: expected a number within") as e:
        load_mapping(p)
    assert len(str(e.value)) < 200
    p.write_text("version = 1\nx = " + "[" * 3000 + "]" * 3000 + "\n")
    with pytest.raises(ConfigError, match=r"m\.toml: .*nested too deep"):
        load_mapping(p)


def test_quote_keeps_error_lines_short() -> None:
    assert quote("x" * 20000).endswith("(20002 chars)") and len(quote("x" * 20000)) < 80
    assert "digits" in quote(10**5000)
    assert quote("a\nb") == "'a\\nb'"
    with pytest.raises(BadFile, match=r"f:1: rate: expected a number >= 1 and <= 10, got an integer of about"):
        number(10**400, "f:1: rate", 1, 10)
    with pytest.raises(BadFile, match="expected a finite number"):
        number(float("nan"), "f: x")


@pytest.mark.parametrize("text", ["[" * 100_000 + "]" * 100_000, '{"a": NaN}', '{"a": 1e999}', '{"a": ' + "1" * 5000 + "}",
                                  "[" * 40 + "]" * 40])
def test_bounded_json_refuses_what_would_break_a_reader(text: str) -> None:
    with pytest.raises(BadFile, match="^f.json"):
        load_json(text, "f.json", "test file")


def test_bounded_toml_names_the_line() -> None:
    with pytest.raises(BadFile, match=r"^f.toml:2:\d+: TOML syntax error"):
        load_toml("a = 1\nb = = 2\n", "f.toml", "test file")
    assert load_toml("a = [[1, 2], [3]]\n", "f.toml", "test file") == {"a": [[1, 2], [3]]}
    # a file cut short on its last line: tomllib says "at end of document", which was reported as 1:1
    for text, where in (('version = 1\n[[binding]]\ncontrol=', ":3:9:"), ('x = "abc', ":1:9:"),
                        ('a = 1\nb = [1,\n\n', ":2:8:")):
        with pytest.raises(BadFile, match="^f.toml" + where) as err:
            load_toml(text, "f.toml", "test file")
        assert "end of the file" in str(err.value)


def test_a_rig_array_header_promising_terabytes_is_refused_before_numpy_allocates(tmp_path: Path) -> None:
    import damage
    from sim.rig import RigFileError, load_rig

    good = formats.good_rig(tmp_path)
    with np.load(tmp_path / "good.npz", allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files if k != "vertices"}
    (tmp_path / "forged.npz").write_bytes(
        damage.npz_bytes(arrays, {"vertices": damage.npy_forged((10**11, 3))}))
    assert good
    with pytest.raises(RigFileError, match=r"forged\.npz: array 'vertices\.npy' promises 2400000000000 bytes"):
        load_rig(tmp_path / "forged.npz")


@pytest.mark.parametrize("suffix,forge", [
    (".stl", lambda b: b[:80] + (2**32 - 1).to_bytes(4, "little") + b[84:]),
    (".ply", lambda b: b.replace(b"element vertex 120", b"element vertex 99999999999")),
])
def test_a_mesh_count_asking_for_more_than_the_file_holds_is_one_line(tmp_path: Path, suffix: str, forge) -> None:
    from sim.face.transfer import TransferError, read_mesh

    good = formats.good_stl(tmp_path) if suffix == ".stl" else formats.good_ply_bin(tmp_path)
    p = tmp_path / f"head{suffix}"
    p.write_bytes(forge(good))
    with pytest.raises(TransferError, match=rf"head\{suffix}: .*(84 \+ 50 x 4294967295|promises 99999999999)"):
        read_mesh(p)


@pytest.mark.parametrize("encoding", ["utf-16", "utf-16-be", "utf-32"])
def test_a_recording_resaved_as_utf16_is_one_line_with_the_hint(tmp_path: Path, capsys: pytest.CaptureFixture,
                                                                encoding: str) -> None:
    """A take re-saved by an editor as UTF-16: json reads such a header line by itself, and the
    take replayed as an empty one (exit 0, a warning about line 2): the performance silently gone.
    It is one line naming the file and the encoding, exit 2; a UTF-8 byte-order mark still reads."""
    from puppet.cli import main

    good = formats.good_recording(tmp_path).decode()
    p = tmp_path / "saved.jsonl"
    p.write_bytes(good.encode(encoding))
    assert main(["replay", str(p), "--headless"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "saved.jsonl:1" in err and "UTF-" in err and "UTF-8" in err, err
    p.write_bytes(b"\xef\xbb\xbf" + good.encode())
    assert main(["replay", str(p), "--headless"]) == 0
    assert "replayed 24 ticks" in capsys.readouterr().out


@pytest.mark.parametrize(("args", "says"), [(["--speed", "5e-324"], "frames asked"),
                                            (["--to", "-5"], "--to -5 must be at least 0"),
                                            (["--from", "0.04", "--to", "0.02"], "is after --to")])
def test_odd_replay_spans_are_one_line_naming_the_option(tmp_path: Path, capsys: pytest.CaptureFixture,
                                                         args: list[str], says: str) -> None:
    """A speed so small the frame count overflows was an OverflowError traceback; `--to -5` said
    "--from 0.0 must lie in 0..-5.000 s", naming the option the user did not give."""
    from puppet.cli import main

    formats.good_recording(tmp_path)
    assert main(["replay", str(tmp_path / "good.jsonl"), "--out", str(tmp_path / "o.csv"), *args]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and says in err, err
    assert not (tmp_path / "o.csv").exists()
