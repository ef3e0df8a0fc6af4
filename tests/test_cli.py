import subprocess
import sys


def test_puppet_help_lists_commands() -> None:
    out = subprocess.run(
        [sys.executable, "-m", "puppet", "--help"], capture_output=True, text=True, check=True
    )
    assert "usage: puppet" in out.stdout


def test_unknown_command_is_an_error() -> None:
    out = subprocess.run(
        [sys.executable, "-m", "puppet", "no-such-command"], capture_output=True, text=True
    )
    assert out.returncode == 2


def test_each_command_is_found_by_the_name_it_is_typed_with() -> None:
    """A command's own module alone serves `puppet COMMAND ...`; the table naming them must hold
    every command each module registers (else that command would be unknown), and nothing else."""
    import argparse
    import importlib

    from puppet.cli import COMMANDS

    for module, names in COMMANDS:
        sub = argparse.ArgumentParser().add_subparsers()
        importlib.import_module(module).register(sub)
        assert tuple(sub.choices) == names, module


def test_a_command_parses_the_same_with_only_its_module_loaded() -> None:
    from puppet.cli import build_parser

    for argv in (["batch", "export", "takes", "--out", "renders", "--to", "pc2", "--scheduler", "tcp://h:1"],
                 ["monitor", "mock://x.json"], ["takes", "search", "performer:ana"],
                 ["replay", "take.jsonl", "--out", "take.pc2"]):
        alone, whole = build_parser(argv), build_parser()
        assert len(alone._subparsers._group_actions[0].choices) < len(whole._subparsers._group_actions[0].choices)
        a, w = vars(alone.parse_args(argv)), vars(whole.parse_args(argv))
        assert a.keys() == w.keys() and all(a[k] == w[k] for k in a if k != "func"), argv
        assert a["func"] is w["func"]


def test_a_command_module_loads_only_when_its_command_runs() -> None:
    out = subprocess.run([sys.executable, "-c", "import sys; from puppet.cli import main; main(['channels']); "
                          "print(sorted(m for m in sys.modules if m.startswith('puppet.cmd_')))"],
                         capture_output=True, text=True, check=True)
    assert out.stdout.strip().splitlines()[-1] == "['puppet.cmd_channels']"
    help_all = subprocess.run([sys.executable, "-m", "puppet", "--help"], capture_output=True, text=True, check=True)
    for word in ("live", "batch", "monitor", "import-face", "takes"):
        assert word in help_all.stdout


def test_a_mistyped_face_is_the_only_line(tmp_path) -> None:
    """`puppet live --face ...` with no box and no display: the face is wrong, so the demo is not
    announced first; one line, exit 2 (the same for a damaged saved identity)."""
    import os

    env = dict(os.environ, PUPPET_DATA_DIR=str(tmp_path), PUPPET_LIBRARY="off")
    env.pop("DISPLAY", None)
    (tmp_path / "broken.json").write_text("{bad")
    for face in ("ict?identity=abc", "nosuch", "broken"):
        r = subprocess.run([sys.executable, "-m", "puppet", "live", "--headless", "--duration", "1", "--face", face],
                           capture_output=True, text=True, env=env, cwd=tmp_path, timeout=120)
        assert r.returncode == 2 and r.stderr.count("\n") == 1 and "demo" not in r.stderr, (face, r.stderr)


def test_an_error_naming_a_pasted_huge_value_stays_one_short_line() -> None:
    """A device spec of thousands of characters (a paste gone wrong) is named by its start and end:
    one line, exit 2, not a screen of it."""
    spec = "mock://" + "a" * 5000 + "x.toml"
    r = subprocess.run([sys.executable, "-m", "puppet", "monitor", spec], capture_output=True, text=True, timeout=120)
    assert r.returncode == 2
    [line] = r.stderr.strip().splitlines()
    assert line.startswith("puppet: error: mock://aaaa") and "a...a" in line and "ax.toml" in line and len(line) < 500


def test_templates_refuse_an_unbounded_gain(tmp_path, capsys) -> None:
    """`puppet templates --gain inf` (or 1e308) drew pictures flooded by one arrow and reported them
    written; it is one line naming the bound, exit 2, nothing written."""
    from puppet.cli import main

    for gain in ("inf", "1e308", "nan", "0"):
        out = tmp_path / f"t{gain}"
        assert main(["templates", "--out", str(out), "--gain", gain]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "--gain" in err and not out.exists()


def test_templates_into_a_file_says_it_is_a_file(tmp_path, capsys) -> None:
    """`--out` naming a file said "cannot create the folder: File exists"; it says a file is there
    and that --out names a folder, and the file is kept."""
    from puppet.cli import main

    out = tmp_path / "notes.csv"
    out.write_text("keep me\n")
    assert main(["templates", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "a file is there" in err and "folder" in err, err
    assert out.read_text() == "keep me\n"


def test_a_device_named_twice_is_one_line_saying_so() -> None:
    """`--device osc://127.0.0.1:9300 --device osc://127.0.0.1:9300` said the port was 'in use by
    another program' (it was this show's own first device); a box twice is named as the mistake."""
    import pytest

    from puppet.cmd_live import _open_devices
    from puppet.errors import PuppetError

    with pytest.raises(PuppetError, match=r"--device mock://\?sine=dial0 is given twice"):
        _open_devices(["mock://?sine=dial0", "keyboard://", "mock://?sine=dial0"], print)
    devs = _open_devices(["mock://?sine=dial0", "mock://?sine=dial1"], print)
    assert len(devs) == 2
    for d in devs:
        d.close()


def _help(*argv: str) -> str:
    import contextlib
    import io

    import pytest

    from puppet.cli import main

    out = io.StringIO()
    with contextlib.redirect_stdout(out), pytest.raises(SystemExit):
        main([*argv, "--help"])
    return " ".join(out.getvalue().split())


def test_the_helps_say_what_the_commands_do() -> None:
    """Checked against what each command does: `pose --resolution` said 0 ~ 700 vertices (the face
    has 860) and 1 ~ 3k (2,715); `devices` named serial, HID and CAN but lists MIDI ports and audio
    inputs too; `import-face` said it transfers the default face's rig, which is the scanned head
    now, while it transfers the procedural face's."""
    import re

    import sim.face

    text = _help("pose")
    for res, approx in re.findall(r"(\d) ~ ([\d.]+k?)", text):
        n = float(approx.rstrip("k")) * (1000 if approx.endswith("k") else 1)
        real = sim.face.default_model(int(res)).n_vertices
        assert abs(n - real) <= 0.05 * real, (res, approx, real)
    devices = _help("devices")
    assert "MIDI" in devices and "audio" in devices, devices
    imported = _help("import-face")
    assert "procedural face's rig" in imported and "default face's rig" not in imported, imported


def test_templates_and_recognize_take_the_face_as_fit_and_replay_do(tmp_path, capsys) -> None:  # type: ignore[no-untyped-def]
    """`puppet templates --face procedural` was 'unrecognized arguments' (only --rig), while pose,
    fit and replay take --face; a saved identity or the procedural face could not be drawn."""
    from pathlib import Path

    from puppet.cli import main

    out = Path(tmp_path) / "tpl"
    assert main(["templates", "--face", "procedural", "--out", str(out), "--weight", "0.3"]) == 0
    assert len(list(out.glob("template_*.png"))) == 7 and (out / "templates.png").is_file()
    assert main(["templates", "--face", "nobody-saved-this", "--out", str(out)]) == 2
    assert "nobody-saved-this" in capsys.readouterr().err
    assert "--face SPEC" in _help("recognize")
