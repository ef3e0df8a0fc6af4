"""The OSC and face-tracking default maps through the mapping engine: generic addresses reach
channels (in their units), AUs and expressions; TouchOSC's Simple layout moves the face; the ARKit
map is the inverse of the ARKit export; dials layer on top of tracking by the combine rules."""

from __future__ import annotations

import random

import numpy as np
import pytest

from devices.events import ControlEvent
from devices.facestream import ARKIT_NAMES, ROTATION_NAMES
from puppet.errors import ConfigError
from puppet.export.arkit import ARKIT_SHAPES, GAZE_LIDS, SHAPE_SPAN, arkit_row, rotation_row
from puppet.mapping import Mapper, Vocabulary, parse_mapping
from puppet.mapping.defaults import default_map_name, load_default_map, map_names, merge

OSC = "osc://127.0.0.1:9000"
LIVE = "livelink://127.0.0.1:11111"
DT = 1 / 60


@pytest.fixture(scope="module")
def vocab() -> Vocabulary:
    from sim.channels import CHANNEL_SPECS
    from sim.facs import AU_TABLE, EXPRESSIONS
    from puppet.mapping import ChannelInfo

    return Vocabulary([ChannelInfo(c.name, c.kind, c.lo, c.hi, c.default) for c in CHANNEL_SPECS],
                      AU_TABLE, EXPRESSIONS)


def run(m: Mapper, events: list[ControlEvent], ticks: int = 1) -> dict[str, float]:
    for e in events:
        m.feed(e)
    for _ in range(ticks):
        v = m.step(DT)
    return {c.name: float(v[i]) for i, c in enumerate(m.vocab.channels)}


def axis(control: str, value: float, device: str = OSC) -> ControlEvent:
    return ControlEvent(device, control, "axis", value)


def button(control: str, down: bool, device: str = OSC) -> ControlEvent:
    return ControlEvent(device, control, "button", float(down))


def osc_mapper(vocab: Vocabulary, spec: str = OSC) -> Mapper:
    name = default_map_name(spec)
    assert name in map_names()
    return Mapper(merge([(load_default_map(name), spec)]), vocab)


def test_each_profile_and_stream_has_its_map() -> None:
    assert default_map_name("osc://127.0.0.1:9000") == "osc_generic"
    assert default_map_name("osc://127.0.0.1:9000?profile=touchosc") == "osc_touchosc"
    assert default_map_name("osc://:9000?lan=1&profile=openstage") == "osc_openstage"
    for scheme in ("facecap", "vmc", "ifacialmocap", "livelink"):
        assert default_map_name(f"{scheme}://127.0.0.1:1") == "arkit"


def test_generic_addresses_reach_channels_aus_and_expressions(vocab: Vocabulary) -> None:
    m = osc_mapper(vocab)
    v = run(m, [axis("/face/channel/zygomaticus_major_l", 0.8), axis("/face/channel/age", 70.0),
                axis("/face/channel/eyes_yaw", -0.4), axis("/face/channel/frontalis_outer", 0.5)])
    assert v["zygomaticus_major_l"] == pytest.approx(0.8) and v["zygomaticus_major_r"] == 0.0
    assert v["age"] == pytest.approx(70.0) and v["eyes_yaw"] == pytest.approx(-0.4)  # channel units
    assert v["frontalis_outer_l"] == v["frontalis_outer_r"] == pytest.approx(0.5)  # a pair by its name
    m = osc_mapper(vocab)
    au12 = m.vocab.au_weights("AU12")
    v = run(m, [axis("/face/au/12", 0.5)])
    for i, w in au12.items():
        assert v[vocab.channels[i].name] == pytest.approx(0.5 * w)
    m = osc_mapper(vocab)
    v = run(m, [axis("/face/expression/happiness", 1)])
    want = m.vocab.resolve("expr:happiness")
    for i, w in want.channels:
        assert v[vocab.channels[i].name] == pytest.approx(w)
    v = run(m, [axis("/face/expression/happiness", 0)])
    assert all(v[vocab.channels[i].name] == 0.0 for i, _ in want.channels)


def test_unknown_addresses_change_nothing(vocab: Vocabulary) -> None:
    m = osc_mapper(vocab)
    rest = run(m, [])
    assert run(m, [axis("/face/channel/nosuch", 1.0), axis("/face/au/99", 1.0), axis("/other", 1.0)]) == rest


def test_a_template_with_a_bad_target_is_one_located_error(vocab: Vocabulary) -> None:
    text = 'version = 1\n[[binding]]\ncontrol = "/x/{channel}"\ntarget = "{channel}_bogus"\n'
    with pytest.raises(ConfigError, match=r"mine.toml:4:1: unknown target"):
        Mapper(parse_mapping(text, "mine.toml"), vocab)


def test_touchosc_simple_layout_moves_the_face(vocab: Vocabulary) -> None:
    spec = "osc://127.0.0.1:9000?profile=touchosc"
    m = osc_mapper(vocab, spec)
    v = run(m, [axis("/1/fader4", 0.7, spec), axis("/1/fader1", 0.9, spec), axis("/3/xy:0", 1.0, spec)], ticks=90)
    assert v["jaw"] == pytest.approx(0.7, abs=1e-3)  # no pickup needed: the fader jumps
    assert v["zygomaticus_major_l"] == pytest.approx(0.9, abs=1e-3) == v["zygomaticus_major_r"]
    assert v["eyes_yaw"] == pytest.approx(1.0, abs=1e-3)
    v = run(m, [button("/2/push3", True, spec), button("/2/push3", False, spec)], ticks=90)
    surprise = m.vocab.resolve("expr:surprise")
    assert all(v[vocab.channels[i].name] >= w - 1e-3 for i, w in surprise.channels)
    assert ("osc://127.0.0.1:9000?profile=touchosc", "/2/push3", True) in m.light_changes()


def test_openstage_widgets_move_the_face(vocab: Vocabulary) -> None:
    spec = "osc://127.0.0.1:9000?profile=openstage"
    m = osc_mapper(vocab, spec)
    v = run(m, [axis("/fader_7", 0.4, spec), axis("/knob_1", 0.6, spec)], ticks=90)
    assert v["jaw"] == pytest.approx(0.4, abs=1e-3) and v["zygomaticus_major_l"] == pytest.approx(0.6)


def _arkit_events(values: np.ndarray, names: list[str]) -> list[ControlEvent]:
    index = {n: i for i, n in enumerate(names)}
    row = arkit_row(values, index)
    turns = [axis(n, v, LIVE) for n, v in zip(ROTATION_NAMES, rotation_row(values, index))]
    return [axis(shape[0].lower() + shape[1:], w, LIVE) for shape, w in zip(ARKIT_SHAPES, row)] + turns


def test_any_pose_exported_and_streamed_back_exports_the_same_weights(vocab: Vocabulary) -> None:
    """Any pose of the face (not only one a stream of shapes gives) exported as ARKit weights and
    streamed back returns as a pose that exports the same weights and streams back as itself: a
    channel other shapes also drive (pressed lips lift the chin, a sneer narrows the eye, the gaze
    lifts the lid) writes its own shape only for what their shares leave unexplained."""
    names = [c.name for c in vocab.channels]
    index = {n: i for i, n in enumerate(names)}
    rng = np.random.default_rng(11)
    worst = 0.0
    for _ in range(40):
        values = np.array([c.default for c in vocab.channels], float)
        for i, c in enumerate(vocab.channels):
            if rng.random() < 0.4:
                values[i] = rng.uniform(max(c.lo, -1.0), min(c.hi, 1.0))
        m = Mapper(merge([(load_default_map("arkit"), LIVE)]), vocab)
        once = run(m, _arkit_events(values, names))
        back = np.array([once[n] for n in names])
        m = Mapper(merge([(load_default_map("arkit"), LIVE)]), vocab)
        twice = run(m, _arkit_events(back, names))
        assert arkit_row(np.array([twice[n] for n in names]), index) == pytest.approx(arkit_row(back, index), abs=1e-9)
        for n in names:
            assert twice[n] == pytest.approx(once[n], abs=1e-9), n
        worst = max(worst, max(abs(a - b) for a, b in zip(arkit_row(back, index), arkit_row(values, index))))
    assert worst > 0.05  # the poses were not all ones the shapes carry: the test has teeth


def test_arkit_map_is_the_inverse_of_the_export(vocab: Vocabulary, arkit_expressible) -> None:  # type: ignore[no-untyped-def]
    """A pose exported as ARKit weights and streamed back comes back as the same pose, for every
    channel the export can express (procerus folds into browDown with corrugator: kept below it)."""
    names = [c.name for c in vocab.channels]
    assert [s[0].lower() + s[1:] for s in ARKIT_SHAPES] == list(ARKIT_NAMES)
    covered = {"orbicularis_oculi_lid", "orbicularis_oculi", "levator_labii_alaeque_nasi", "zygomaticus_major",
               "depressor_anguli_oris", "buccinator", "risorius", "depressor_labii", "levator_labii",
               "frontalis_outer", "corrugator", "levator_palpebrae"}
    rng = random.Random(5)
    for _ in range(5):
        values = np.array([c.default for c in vocab.channels])
        for base in covered:
            for side in ("_l", "_r"):
                values[names.index(base + side)] = rng.uniform(0.2, 1.0)
        # a shape calibrated to the scans (SHAPE_SPAN) expresses its channel up to that span
        values[names.index("corrugator_l")] = rng.uniform(0.2, SHAPE_SPAN.get("BrowDown", 1.0))
        values[names.index("corrugator_r")] = rng.uniform(0.2, SHAPE_SPAN.get("BrowDown", 1.0))
        inner = rng.uniform(0, SHAPE_SPAN["BrowInnerUp"])
        values[names.index("frontalis_inner_l")] = values[names.index("frontalis_inner_r")] = inner
        values[names.index("procerus")] = 0.1
        values[names.index("jaw")] = rng.uniform(0, 1)
        # each side's press is that side's half of the lips' sphincter; the whole one is what the
        # lower lip's shrug and the upper lip's roll share of it (below)
        for side in ("_l", "_r"):
            values[names.index("orbicularis_oris" + side)] = rng.uniform(0, SHAPE_SPAN["MouthPress"])
        values[names.index("orbicularis_oris")] = 0.0
        values[names.index("mentalis")] = rng.uniform(0, 1.0)
        values[names.index("eyes_yaw")] = rng.uniform(-1, 1)
        values[names.index("eyes_pitch")] = rng.uniform(-1, 1)
        # the eyes turned towards or away from each other, each eye within its range (yaw +- vergence)
        values[names.index("eyes_vergence")] = rng.uniform(-1, 1) * (1.0 - abs(values[names.index("eyes_yaw")]))
        for ch in ("head_yaw", "head_pitch", "head_roll", "jaw_sideways"):
            values[names.index(ch)] = rng.uniform(-0.8, 0.8)
        for ch in ("jaw_forward", "lip_closure", "incisivus", "orbicularis_oris_marginalis_upper",
                   "orbicularis_oris_marginalis_lower", "mouth_shift_l", "mouth_shift_r", "cheek_puff", "tongue_out",
                   "orbicularis_oris_peripheralis_lower"):
            values[names.index(ch)] = rng.uniform(0, 0.7)
        # a funnel everts both lips: a pose comes back whole when the upper lip is everted at least as far
        values[names.index("orbicularis_oris_peripheralis_upper")] = rng.uniform(0.7, 1.0)
        # a calibrated shape expresses its channels up to its span, and a shape that shares another
        # channel (pressed lips lift the chin, puffed cheeks purse the lips, ...) comes back whole
        # when that channel is at least the shape's share
        arkit_expressible(values, names)
        # the lids follow the gaze: a pose comes back whole when its lids are at least the gaze's share
        up, down = max(values[names.index("eyes_pitch")], 0.0), max(-values[names.index("eyes_pitch")], 0.0)
        for side in ("_l", "_r"):
            for lid, look in (("levator_palpebrae", up), ("orbicularis_oculi_lid", down)):
                share = GAZE_LIDS["EyeLookUp" if lid == "levator_palpebrae" else "EyeLookDown"][1]
                values[names.index(lid + side)] = max(values[names.index(lid + side)], share * look)
        m = Mapper(merge([(load_default_map("arkit"), LIVE)]), vocab)
        back = run(m, _arkit_events(values, names))
        for i, n in enumerate(names):
            if n in ("procerus", "age") or n.startswith(("zygomaticus_minor", "levator_anguli")):
                continue  # procerus reads max(corrugator, procerus); the others ARKit has no shape for
            assert back[n] == pytest.approx(values[i], abs=1e-9), n


def test_dials_layer_on_top_of_tracking(vocab: Vocabulary) -> None:
    # mouthFrown drives its one channel 1:1 (mouthSmile drives the zygomaticus at 0.55 of it and
    # the corner's other muscles by shares: puppet/export/arkit.py SHAPE_SPAN, SHAPE_SHARES)
    dial_map = parse_mapping('version = 1\n[[binding]]\ncontrol = "dial1"\ntarget = "depressor_anguli_oris"\n'
                             '[[binding]]\ncontrol = "/2/push11"\ntarget = "eyes_yaw"\nto = [0.0, 0.3]\n', "dials.toml")
    box, osc = "sgi:///dev/ttyS0", "osc://127.0.0.1:9000?profile=touchosc"
    spec = merge([(load_default_map("arkit"), LIVE), (dial_map, None)])
    m = Mapper(spec, vocab)
    v = run(m, [axis("mouthFrownLeft", 0.3, LIVE), axis("mouthFrownRight", 0.3, LIVE),
                axis("eyeLookOutLeft", 0.4, LIVE), axis("eyeLookInRight", 0.4, LIVE)])
    assert v["depressor_anguli_oris_l"] == pytest.approx(0.3) and v["eyes_yaw"] == pytest.approx(0.4)
    v = run(m, [ControlEvent(box, "dial1", "dial", 0.25), button("/2/push11", True, osc)])
    assert v["depressor_anguli_oris_l"] == pytest.approx(0.55)  # the dial continues from the tracked frown
    assert v["eyes_yaw"] == pytest.approx(0.7)  # gaze sums: tracking + the look button
    v = run(m, [axis("mouthFrownLeft", 0.9, LIVE)])
    assert v["depressor_anguli_oris_l"] == pytest.approx(0.9)  # max: tracking beyond the dial wins
    assert v["depressor_anguli_oris_r"] == pytest.approx(0.55)


@pytest.mark.parametrize("name", ["osc_generic", "osc_touchosc", "arkit"])
def test_damaged_maps_give_one_line_or_a_result(name: str, vocab: Vocabulary) -> None:
    """Generated damaged variants of the shipped maps (fixed seed): each one loads or fails with a
    single ConfigError line naming the file and line, never anything else."""
    from puppet.mapping.defaults import map_text

    text = map_text(name)
    rng = random.Random(1234)
    junk = ["{channel}", "{au}", "{expression}", "\"", "[", "]]", "=", "\n", "{", "nan", "-1e400", "{au}{au}"]
    for k in range(40):
        chars = list(text)
        for _ in range(rng.randint(1, 4)):
            i = rng.randrange(len(chars))
            op = rng.randrange(3)
            if op == 0:
                del chars[i:i + rng.randint(1, 12)]
            elif op == 1:
                chars.insert(i, rng.choice(junk))
            else:
                chars[i] = rng.choice(junk)
        bad = "".join(chars)
        try:
            Mapper(parse_mapping(bad, f"{name}-{k}.toml"), vocab)
        except ConfigError as err:
            msg = str(err)
            assert msg.startswith(f"{name}-{k}.toml:") and "\n" not in msg.strip(), msg


@pytest.mark.parametrize("weight", [0.2, 0.9])
def test_each_arkit_shape_alone_drives_the_same_channels_through_the_map_and_the_import(
        vocab: Vocabulary, weight: float) -> None:
    """One shape streamed through the shipped map and read from a CSV (`shape_channels`) give the
    same pose, spans and shares included; a left shape leaves the face's right side at rest."""
    from puppet.capture.arkit_in import shape_channels
    from sim.channels import CHANNEL_NAMES

    rest = {c.name: c.default for c in vocab.channels}
    for shape in ARKIT_SHAPES:
        m = Mapper(merge([(load_default_map("arkit"), LIVE)]), vocab)
        streamed = run(m, [axis(shape[0].lower() + shape[1:], weight, LIVE)])
        read = dict(zip(CHANNEL_NAMES, shape_channels({shape: np.full(1, weight)}, 1)[0]))
        for name, v in streamed.items():
            assert v == pytest.approx(read[name], abs=1e-9), (shape, name)
        if shape.endswith("Left"):
            moved = [n for n, v in streamed.items() if n.endswith("_r") and v != rest[n]]
            assert not moved, (shape, moved)
