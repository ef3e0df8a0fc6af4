"""A show whose face is slow to load (empty caches: the first show after an install) says so while
it loads, instead of a silent minute before the first line."""

from __future__ import annotations

import time
from pathlib import Path

import pytest

from puppet import cmd_live, live
from puppet.cli import main
from puppet.errors import PuppetError

SCRIPT = Path(__file__).resolve().parents[2] / "examples" / "mock" / "sgi_rehearsal.toml"


def test_a_slow_face_load_is_announced_while_it_loads(monkeypatch: pytest.MonkeyPatch,
                                                      capsys: pytest.CaptureFixture) -> None:
    def slow_load(*args: object, **kwargs: object) -> None:
        time.sleep(1.0)  # the notice is due after SLOW_FACE_NOTICE (set far shorter below)
        raise PuppetError("the face stops here")

    monkeypatch.setattr(live, "load_face", slow_load)
    monkeypatch.setattr(cmd_live, "SLOW_FACE_NOTICE", 0.05)
    monkeypatch.setenv("PUPPET_LIBRARY", "off")
    code = main(["live", "--headless", "--no-panel", "--no-realtime", "--device", f"mock://{SCRIPT}",
                 "--duration", "1"])
    _assert_notice_before_the_stop(code, capsys.readouterr().err)


@pytest.mark.parametrize("argv", [["live", "--headless", "--no-panel", "--no-realtime"],  # no box: the demo
                                  ["live", "--demo", "--headless", "--no-panel", "--no-realtime"]],
                         ids=["no box, no display", "--demo"])
def test_the_demo_says_so_too_while_its_face_loads(argv: list[str], monkeypatch: pytest.MonkeyPatch,
                                                   capsys: pytest.CaptureFixture) -> None:
    """The README's first command on a new install (no display, no box: the built-in demo) said
    "performing the built-in demo (about 20 s)" and then nothing for 3-4 minutes while the face and
    its compiled parts were built (seen at load 15); the show with a box said it was preparing."""
    def slow_load(*args: object, **kwargs: object) -> None:
        time.sleep(1.0)
        raise PuppetError("the face stops here")

    monkeypatch.setattr(live, "load_face", slow_load)
    monkeypatch.setattr(live, "display_available", lambda: False)
    monkeypatch.setattr(cmd_live, "SLOW_FACE_NOTICE", 0.05)
    monkeypatch.setattr(cmd_live, "_open_devices", lambda specs, warn: [])
    monkeypatch.setenv("PUPPET_LIBRARY", "off")
    code = main(argv)
    _assert_notice_before_the_stop(code, capsys.readouterr().err)


def test_the_headless_demo_says_it_prepares_the_face(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                    capsys: pytest.CaptureFixture) -> None:
    """The headless demo runs on its script's clock; its show left out "preparing the face", so
    the minutes numba spent compiling on a new install passed without a word after "about 20 s"."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(live, "display_available", lambda: False)
    monkeypatch.setenv("PUPPET_LIBRARY", "off")
    code = main(["live", "--demo", "--headless", "--no-panel", "--no-realtime", "--duration", "0.1"])
    err = capsys.readouterr().err
    assert code == 0, err
    assert "puppet: preparing the face" in err.splitlines(), err


def _assert_notice_before_the_stop(code: int, err: str) -> None:
    """The run stopped on the slow face's error (exit 2) after saying it was preparing the face."""
    assert code == 2, err
    lines = err.splitlines()
    notice = [i for i, line in enumerate(lines) if line.startswith("puppet: preparing the face")]
    stop = [i for i, line in enumerate(lines) if "the face stops here" in line]
    assert notice and stop and notice[0] < stop[0], err
