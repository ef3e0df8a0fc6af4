"""The page's pieces without a browser: its message decoder under damaged input, channel limits,
its map through the real mapper, the curves format version 2, and `puppet learn` from a page."""

from __future__ import annotations

import argparse
import asyncio
import io
import json
import random
import socket
import threading
import time
from pathlib import Path

import aiohttp
import numpy as np
import pytest

from devices.events import ControlEvent, StatusEvent
from puppet.curves import CurveLayer, format_curves, parse_curves
from puppet.errors import ConfigError
from puppet.live import load_face
from puppet.mapping import Mapper
from puppet.panel.device import decode_input, parse_roles
from puppet.panel.layout import allowed_controls, build_layout, controls_of, panel_map, region_of


@pytest.fixture(scope="module")
def vocab():
    return load_face().vocab


def test_decoder_ignores_an_integer_past_floats(vocab) -> None:
    """`{"t":"in","c":...,"v":1000...0}` with 400 digits (within the 4096-byte limit): float() raised
    OverflowError, which ended that page's connection with aiohttp's traceback on the show's terminal."""
    allowed = allowed_controls(vocab, ["jaw"])
    for digits in ("1" + "0" * 400, "-1" + "0" * 400):
        assert decode_input('{"t":"in","c":"slider:jaw","v":%s}' % digits, allowed) is None


def test_decoder_survives_damaged_messages(vocab) -> None:
    allowed = allowed_controls(vocab, ["jaw"])
    good = '{"t":"in","c":"slider:jaw","v":0.25}'
    assert decode_input(good, allowed) == ("slider:jaw", 0.25)
    assert decode_input('{"t":"in","c":"slider:jaw","v":7}', allowed) == ("slider:jaw", 1.0)
    rng = random.Random(13)
    alphabet = '{}[]":,.-0123456789eEtinvcNaInfinity \\\x00\xff'
    for _ in range(3000):
        s = list(good)
        for _ in range(rng.randint(1, 6)):
            op = rng.random()
            i = rng.randrange(len(s) + 1)
            if op < 0.4 and s:
                del s[min(i, len(s) - 1)]
            elif op < 0.8:
                s.insert(i, rng.choice(alphabet))
            else:
                s[min(i, len(s) - 1)] = rng.choice(alphabet)
        got = decode_input("".join(s), allowed)
        if got is not None:
            ctl, v = got
            assert ctl in allowed and 0.0 <= v <= 1.0
    for bad in ('{"t":"in","c":"slider:frontalis_inner_l","v":1}', '{"t":"in","c":"slider:jaw","v":NaN}',
                '{"t":"in","c":"slider:jaw","v":true}', '[1,2]', '{"t":"in","c":["slider:jaw"],"v":1}', "x" * 10000):
        assert decode_input(bad, allowed) is None


def test_a_page_message_nested_as_deep_as_its_size_allows_is_ignored(vocab) -> None:
    """A message of at most 4096 bytes nests 2048 deep, past json's recursion limit: it is a
    malformed message like any other (it ended the page's connection with aiohttp's traceback
    on the show's terminal)."""
    from puppet.panel.device import MAX_MESSAGE
    from puppet.panel.face import parse_face_message

    allowed = allowed_controls(vocab, ["jaw"])
    for deep in ("[" * (MAX_MESSAGE // 2) + "]" * (MAX_MESSAGE // 2), '{"t":"in","c":' + "[" * 2000 + "]" * 2000 + "}",
                 "[" * 128 + "]" * 128):
        assert decode_input(deep[:MAX_MESSAGE], allowed) is None
        assert parse_face_message(deep[:256]) is None
    assert parse_face_message('{"w":' + "[" * 120 + "]" * 120 + "}") is None


def test_channel_limits(vocab) -> None:
    every = set(controls_of(vocab))
    assert allowed_controls(vocab, None) == every
    eyes = allowed_controls(vocab, ["eyes_*", "orbicularis_oculi*", "AU45"])
    assert {"slider:eyes_yaw", "slider:orbicularis_oculi_lid_l", "pad:AU45", "button:panic"} <= eyes
    assert "slider:jaw" not in eyes and "pad:expr:happiness" not in eyes
    assert "slider:frontalis_inner_r" in allowed_controls(vocab, ["frontalis_inner"])  # a pair's name
    assert parse_roles(["mouth=jaw, orbicularis_oris"]) == {"mouth": ["jaw", "orbicularis_oris"]}
    for bad in ("mouth", "=jaw", "m o=jaw", "mouth="):
        with pytest.raises(ValueError):
            parse_roles([bad])


def test_a_role_naming_no_control_is_refused(vocab) -> None:
    # a typo (`mouth=jaww`) served a page of nothing but panic and marker, silently
    assert parse_roles(["mouth=jaw,AU26,frontalis_*"], vocab) == {"mouth": ["jaw", "AU26", "frontalis_*"]}
    for bad in ("mouth=jaww", "mouth=jaw,nosuch"):
        with pytest.raises(ValueError, match="matches no"):
            parse_roles([bad], vocab)


def test_page_map_drives_channels_through_the_mapper(vocab) -> None:
    m = Mapper(panel_map(vocab), vocab)
    names = [c.name for c in vocab.channels]
    dev = "panel://127.0.0.1:1/alice"
    m.feed(StatusEvent(dev, "connected"))
    m.feed(ControlEvent(dev, "slider:jaw", "axis", 0.5, None, 0.5, 0.0))
    m.feed(ControlEvent(dev, "slider:age", "axis", 0.5, None, 0.5, 0.0))
    v = m.step(1 / 60)
    assert v[names.index("jaw")] == 0.5 and v[names.index("age")] == 60.0  # no pickup: at once, in units
    m.feed(ControlEvent(dev, "pad:expr:happiness", "button", 1.0, None, 1, 0.0))
    m.feed(ControlEvent(dev, "pad:expr:happiness", "button", 0.0, None, 0, 0.0))
    for _ in range(30):
        v = m.step(1 / 60)
    assert v[names.index("zygomaticus_major_l")] > 0.5  # radio: latched after the release
    m.feed(StatusEvent(dev, "lost"))
    m.feed(ControlEvent(dev, "button:panic", "button", 1.0, None, 1, 0.0))
    for _ in range(60):
        v = m.step(1 / 60)
    assert np.allclose(v, m.defaults)
    lay = build_layout(vocab)
    rows = [c for r in lay["regions"] for row in r["rows"] for c in row["channels"]]
    assert sorted(rows + ["age"]) == sorted(names)  # every channel has a slider (age: the dial)


V2 = """facepuppet-curves 2
take take.jsonl 0123456789abcdef
curve jaw linear replace
  0.0  0
  0.5  1  step
  1.0  0.5
end
curve jaw smooth add
  2.0  0
  3.0  0.2
end
"""


def test_curves_version_2(vocab) -> None:
    cs = parse_curves(V2, "e.curves")
    assert cs.version == 2 and cs.take == ("take.jsonl", "0123456789abcdef")
    jaw = cs.curves[0]
    assert jaw.at(0.25) == pytest.approx(0.5) and jaw.at(0.75) == 1.0 and jaw.at(1.0) == 0.5  # step segment
    assert parse_curves(format_curves(cs), "again").curves[0].segs == jaw.segs
    layer = CurveLayer(cs, vocab)
    base = np.array(vocab.defaults())
    j = [c.name for c in vocab.channels].index("jaw")
    assert layer.apply(base, 1.5)[j] == base[j]  # between the curves: the take shows through
    with pytest.raises(ConfigError, match="e.curves:5"):
        parse_curves(V2.replace("1  step", "1  bezier"), "e.curves")
    with pytest.raises(ConfigError, match="v1.curves:4"):  # version 1 has no segment word
        parse_curves(V2.replace(" 2\ntake take.jsonl 0123456789abcdef", " 1"), "v1.curves")


def test_damaged_curves_files_give_one_line(tmp_path: Path) -> None:
    from puppet.curves import load_curves

    rng = random.Random(13)
    data = V2.encode()
    for n in range(200):
        b = bytearray(data)
        for _ in range(rng.randint(1, 8)):
            i = rng.randrange(len(b))
            op = rng.random()
            if op < 0.3:
                del b[i]
            elif op < 0.6:
                b.insert(i, rng.choice(b" \n\x00\xff-.e9#abc"))
            else:
                b[i] = rng.randrange(256)
        p = tmp_path / f"d{n}.curves"
        p.write_bytes(bytes(b))
        try:
            load_curves(p)
        except ConfigError as err:
            msg = str(err)
            assert msg.startswith(str(p)) and "\n" not in msg


def _free_port() -> int:
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


def test_learn_binds_a_page_slider(tmp_path: Path) -> None:
    from puppet import cmd_learn

    port = _free_port()
    mapfile = tmp_path / "show.toml"
    args = argparse.Namespace(device=[f"panel://127.0.0.1:{port}"], map=str(mapfile), timeout=4.0)
    out: dict[str, int] = {}
    t = threading.Thread(target=lambda: out.setdefault("rc", cmd_learn.run(args, io.StringIO("expr:happiness\n"))))
    t.start()

    async def touch() -> None:
        deadline = time.monotonic() + 60
        while True:
            try:
                async with aiohttp.ClientSession() as s, s.ws_connect(f"http://127.0.0.1:{port}/ws?name=desk") as ws:
                    hello = json.loads((await ws.receive(timeout=5)).data)
                    assert hello["you"] == "desk"
                    for v in (0.0, 0.1, 0.2, 0.3):
                        await ws.send_str(json.dumps({"t": "in", "c": "slider:jaw", "v": v}))
                        await asyncio.sleep(0.05)
                    await asyncio.sleep(1.0)
                    return
            except (aiohttp.ClientError, OSError):
                if time.monotonic() > deadline:
                    raise
                await asyncio.sleep(0.2)

    asyncio.run(touch())
    t.join(60)
    assert out.get("rc") == 0
    text = mapfile.read_text()
    assert 'control = "slider:jaw"' in text and 'target = "expr:happiness"' in text and 'device = "panel"' in text


def test_every_channel_of_the_face_sits_in_its_face_region() -> None:
    """The page groups sliders by face region: no channel of the default face falls into "other"
    (a new muscle channel has to be placed), and the lid muscles sit with the eyes."""
    from sim.channels import CHANNEL_SPECS

    for spec in CHANNEL_SPECS:
        if spec.kind != "age":
            assert region_of(spec.name) != "other", spec.name
    assert region_of("levator_palpebrae_l") == region_of("orbicularis_oculi_lid_r") == "eyes"


def test_page_curves_with_an_integer_past_floats_are_refused_with_the_reason() -> None:
    """A key [0, 1000...0] with 400 digits in the editor's save: math.isfinite raised OverflowError
    (not a ValueError), so the save answered 500 with a traceback on the editor's terminal."""
    from puppet.panel.editor import curves_from_json

    for key in ([0, 10**400], [10**400, 0.5], [0, -(10**400)]):
        with pytest.raises(ValueError, match="finite"):
            curves_from_json([{"target": "jaw", "keys": [key]}], ("take.jsonl", "0" * 16))


def test_the_editors_boxes_with_a_map_that_cannot_be_read_say_so(vocab, tmp_path: Path) -> None:
    """`puppet edit TAKE --device SPEC --map broken.toml`: closing the boxes opened met attributes
    not made yet, and an AttributeError traceback hid the map's one line."""
    from puppet.panel.boxes import BoxFeed

    broken = tmp_path / "broken.toml"
    broken.write_bytes(b"\xff\xfe not a map")
    root = Path(__file__).resolve().parents[2]
    with pytest.raises(ConfigError, match="broken.toml"):
        BoxFeed([f"mock://{root / 'examples' / 'mock' / 'sgi_rehearsal.toml'}"], vocab, str(broken))


def test_the_sided_halves_get_a_row_of_their_own_beside_the_whole(vocab) -> None:
    """The lips' sphincter and the mentalis are a whole channel and a pair of halves: two rows whose
    labels differ, the halves' with a left and a right slider; learn offers each name once."""
    rows = [r for reg in build_layout(vocab)["regions"] for r in reg["rows"]]
    for whole in ("orbicularis_oris", "mentalis"):
        mine = [r for r in rows if r["channels"][0].startswith(whole) and r["channels"][-1] in
                (whole, whole + "_r")]
        assert [r["channels"] for r in mine] == [[whole], [whole + "_l", whole + "_r"]]
        assert len({r["label"] for r in mine}) == 2
    targets = vocab.all_targets()
    assert len(targets) == len(set(targets))
    assert vocab.resolve("orbicularis_oris").channels == ((vocab.index["orbicularis_oris"], 1.0),)
