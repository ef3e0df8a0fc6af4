"""Learn mode: touching controls writes working bindings, keeping the file's comments."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
import tomlkit

from devices.events import ControlEvent
from puppet.errors import ConfigError
from puppet.mapping import Mapper, load_mapping
from puppet.mapping.learn import learn_binding
from puppet_helpers import DT, idx, vocab

SCRIPT = """
impersonate = "sgi"
speed = 0
[[ramp]]
control = "dial3"
start = 0.0
duration = 0.2
from = 0.0
to = 0.3
rate = 50
[[events]]
t = 0.5
control = "button5"
value = 1
[[events]]
t = 0.55
control = "button5"
value = 0
"""

EXISTING = """# my show's map -- keep this comment
version = 1
name = "show"

[[binding]]
control = "dial0"   # the age dial
device = "sgi"
target = "age"
"""


def test_cli_learn_writes_working_bindings_and_keeps_comments(tmp_path: Path) -> None:
    script = tmp_path / "touch.toml"
    script.write_text(SCRIPT)
    mp = tmp_path / "show.toml"
    mp.write_text(EXISTING)
    out = subprocess.run([sys.executable, "-m", "puppet", "learn", "--device", f"mock://{script}", "--map", str(mp),
                          "--timeout", "3"], input="nonsense\njaw\nzygomaticus_major\ntoggle\n",
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert "unknown target 'nonsense'" in out.stdout and "added: dial3 -> jaw" in out.stdout
    text = mp.read_text()
    assert "# my show's map -- keep this comment" in text and "# the age dial" in text
    spec = load_mapping(mp)
    assert [(b.control, b.target) for b in spec.bindings] == [
        ("dial0", "age"), ("dial3", "jaw"), ("button5", "zygomaticus_major")]
    assert spec.bindings[2].mode == "toggle"
    from puppet.live import load_face

    face = load_face()
    m = Mapper(spec, face.vocab)
    names = [c.name for c in face.vocab.channels]
    m.feed(ControlEvent("mock://other.toml", "dial3", "dial", 0.5))  # another script/port of the same kind: still bound
    m.feed(ControlEvent("mock://other.toml", "button5", "button", 1.0))
    for _ in range(120):
        v = m.step(DT)
    assert v[names.index("jaw")] == pytest.approx(0.25, abs=1e-3)
    assert v[names.index("zygomaticus_major_l")] == pytest.approx(1.0, abs=1e-3)


def test_relearn_keeps_settings_and_new_file_is_created(tmp_path: Path) -> None:
    mp = tmp_path / "new.toml"
    assert learn_binding(mp, "button1", "mock://x", "jaw", "button", "trigger") == "added"
    assert learn_binding(mp, "button1", "mock://x", "expr:happiness", "button") == "updated"
    spec = load_mapping(mp)
    assert len(spec.bindings) == 1
    b = spec.bindings[0]
    assert (b.target, b.mode, b.attack, b.device) == ("expr:happiness", "trigger", 0.06, "mock")
    m = Mapper(spec, vocab())
    m.feed(ControlEvent("mock://x", "button1", "button", 1.0))
    assert max(m.step(DT)[idx("zygomaticus_major_l")] for _ in range(6)) > 0.5


def test_learn_refuses_to_touch_a_broken_file(tmp_path: Path) -> None:
    mp = tmp_path / "broken.toml"
    mp.write_text("[[binding]]\ncontrol = \n")
    with pytest.raises(ConfigError, match=r"broken.toml:2:\d+"):
        learn_binding(mp, "dial0", "sgi://", "jaw", "dial")
    assert mp.read_text() == "[[binding]]\ncontrol = \n"


def test_learn_into_a_missing_folder_is_a_config_error(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="cannot write the mapping file"):
        learn_binding(tmp_path / "nope" / "m.toml", "dial0", "sgi://", "jaw", "dial")


@pytest.mark.parametrize("target,event_value,want", [
    ("head_yaw", 0.25, -0.5),  # an absolute axis 0..1 spans the channel's -1..1
    ("incisivus", 0.6, 0.6), ("cheek_puff", 1.0, 1.0), ("jaw_sideways", 1.0, 1.0), ("tongue_out", 0.5, 0.5),
    ("platysma_l", 0.6, 0.6), ("AU18", 1.0, None), ("AU28", 1.0, None), ("AU21", 1.0, None)])
def test_learn_binds_the_new_actions(tmp_path: Path, target: str, event_value: float, want: float | None) -> None:
    """The turn, the lips' and cheeks' actions, the jaw's sideways move and their AUs can be learnt
    onto the face's own channels."""
    from sim.channels import CHANNEL_SPECS
    from sim.facs import AU_TABLE, EXPRESSIONS
    from puppet.mapping import ChannelInfo, Vocabulary

    face = Vocabulary([ChannelInfo(c.name, c.kind, c.lo, c.hi, c.default) for c in CHANNEL_SPECS], AU_TABLE,
                      EXPRESSIONS)
    names = [c.name for c in CHANNEL_SPECS]
    mp = tmp_path / "new.toml"
    assert learn_binding(mp, "slider1", "mock://x", target, "axis") == "added"
    m = Mapper(load_mapping(mp), face)
    for x in (0.0, 0.5, 1.0, event_value):  # a learnt slider picks up where it meets the channel: sweep it
        m.feed(ControlEvent("mock://x", "slider1", "axis", x))
        for _ in range(240):  # past the learnt binding's smoothing
            v = m.step(DT)
    if want is not None:
        assert v[names.index(target)] == pytest.approx(want, abs=0.04)  # (the learnt dead zone at the ends)
    else:
        assert all(v[names.index(ch)] == pytest.approx(w, abs=1e-3) for ch, w in AU_TABLE[target].items())


def test_two_learns_on_one_map_at_once_keep_both_bindings(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Two `puppet learn --map m.toml` at once (two boxes): each read the map, added its binding
    and renamed its copy into place, so the last rename won and the other binding was lost though
    both said 'added'. Here the other learn runs while this one holds its changed copy: both
    bindings are in the map afterwards."""
    import threading

    import puppet.mapping.learn as learn

    mp = tmp_path / "m.toml"
    assert learn_binding(mp, "dial0", "sgi://", "jaw", "dial") == "added"
    dumps, other = learn.tomlkit.dumps, []

    def racing_dumps(doc):  # the first call: this learn's changed copy, not yet written
        monkeypatch.setattr(learn.tomlkit, "dumps", dumps)
        t = threading.Thread(target=lambda: other.append(learn_binding(mp, "dial2", "sgi://", "age", "dial")))
        t.start()
        t.join(2.0)  # the other learn finishes now, or waits for this one to write
        other.append(t)
        return dumps(doc)

    monkeypatch.setattr(learn.tomlkit, "dumps", racing_dumps)
    assert learn_binding(mp, "dial1", "sgi://", "eyes_yaw", "dial") == "added"
    thread = next(x for x in other if isinstance(x, threading.Thread))
    thread.join()
    assert "added" in other
    got = {(b["control"], b["target"]) for b in tomlkit.parse(mp.read_text())["binding"]}
    assert got == {("dial0", "jaw"), ("dial1", "eyes_yaw"), ("dial2", "age")}


@pytest.mark.parametrize("name", ["broken.toml", "missing/show.toml"])
def test_cli_learn_says_the_map_cannot_be_used_before_anything_is_touched(tmp_path: Path, name: str) -> None:
    """A damaged map or one in a folder that is not there was told only after the performer had
    touched a control and named its target (the binding lost); it is told before the first touch,
    one line, exit 2, and nothing is asked."""
    script = tmp_path / "touch.toml"
    script.write_text(SCRIPT)
    mp = tmp_path / name
    if name == "broken.toml":
        mp.write_text("[[binding]\ncontrol = 'dial0'\n")
    out = subprocess.run([sys.executable, "-m", "puppet", "learn", "--device", f"mock://{script}", "--map", str(mp),
                          "--timeout", "3"], input="jaw\n", capture_output=True, text=True, timeout=60)
    errors = [ln for ln in out.stderr.splitlines() if ln.startswith("puppet: error:")]
    assert out.returncode == 2 and len(errors) == 1 and str(mp) in errors[0], out.stderr
    assert "touched" not in out.stdout and "target" not in out.stdout, out.stdout
    assert not (mp.exists() and "jaw" in mp.read_text())
