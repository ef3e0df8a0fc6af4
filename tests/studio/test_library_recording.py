"""The take library while takes are recorded: a take is registered when its recording starts, a
show killed mid-recording leaves an entry that `puppet takes check` completes from what the file
holds, and a take whose file no longer holds it is reported and marked damaged."""

from __future__ import annotations

import json
import os
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import pytest

from puppet.cli import main
from puppet.library.store import Library
from puppet.library.takeinfo import file_hash
from puppet.session import read_session
from takes import write_take

SCRIPT = ('impersonate = "sgi"\nspeed = {speed}\nduration = {duration}\n[[ramp]]\ncontrol = "dial1"\n'
          'start = 0.0\nduration = 0.4\nfrom = 0.0\nto = 1.0\nrate = 50\n')


def takes_json(capsys: pytest.CaptureFixture, lib: Path, *args: str) -> object:
    assert main(["takes", *args, "--library", str(lib), "--json"]) == 0
    return json.loads(capsys.readouterr().out.strip().splitlines()[-1])


def test_a_show_killed_mid_recording_is_listed_and_completed_by_check(tmp_path: Path,
                                                                      capsys: pytest.CaptureFixture) -> None:
    script = tmp_path / "s.toml"
    script.write_text(SCRIPT.format(speed=1, duration=60))
    lib, rec = tmp_path / "takes.db", tmp_path / "show.jsonl"
    proc = subprocess.Popen([sys.executable, "-m", "puppet", "live", "--headless", "--no-panel", "--device",
                             f"mock://{script}", "--record", str(rec), "--library", str(lib), "--performer", "ana",
                             "--tag", "Rehearsal", "--duration", "60", "--tick-rate", "60"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=dict(os.environ))
    try:
        deadline = time.monotonic() + 90
        while time.monotonic() < deadline:  # a good part of the take on disk, and the show still running
            if rec.exists() and rec.read_text().count('"t":"sync"') >= 8:
                break
            assert proc.poll() is None, "the show ended before it was killed"
            time.sleep(0.05)
        else:
            pytest.fail("the recording never got flushed")
        with Library(lib) as library:  # registered while the show runs
            [during] = library.search("")
        assert during["state"] == "recording" and Path(during["path"]) == rec.resolve()
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait(10)
    assert '"t":"end"' not in rec.read_text()

    # the listing completes the entry of the take its show died recording, from what the file holds
    [listed] = takes_json(capsys, lib, "list")
    assert listed["state"] == "crashed" and listed["performer"] == "ana" and listed["tags"] == ["rehearsal"]
    assert listed["devices"] == [f"mock://{script}"] and listed["face"] and listed["recorded"]
    s = read_session(rec)
    assert not s.complete and s.ticks >= 40
    assert listed["duration"] == pytest.approx(s.duration)
    with Library(lib) as library:
        t = library.get(listed["id"])
    assert t["state"] == "crashed" and t["ticks"] == s.ticks
    assert t["hash"] == file_hash(rec)[0] and t["tags"] == ["rehearsal"] and t["performer"] == "ana"
    assert main(["takes", "list", "--library", str(lib)]) == 0
    assert "ended by a crash" in capsys.readouterr().out
    # checked: the take is in place, unchanged
    report = takes_json(capsys, lib, "check", "--no-analyse")
    assert report["ok"] == 1 and report["crashed"] == [] and report["damaged"] == []


def test_a_take_whose_show_died_is_completed_wherever_the_library_is_read(tmp_path: Path,
                                                                         capsys: pytest.CaptureFixture) -> None:
    """Listing, showing, a batch's library query and the page's takes list complete the entry of a
    take whose show died (no `takes check` by hand), and say so on the command line; a take whose
    file no longer holds it is marked damaged."""
    from puppet.batch.plan import select

    lib = tmp_path / "takes.db"
    cut = _killed(write_take(tmp_path / "shoot" / "cut.jsonl", ticks=30, seed=2))
    gone = tmp_path / "shoot" / "gone.jsonl"
    with Library(lib) as library:
        first = library.begin(cut, read_session(cut).header, performer="ana", tags=["wide"])
        second = library.begin(gone, {"tick_rate": 60.0}, performer="bob")
    gone.write_text("not a take\n")
    capsys.readouterr()
    assert main(["takes", "show", str(first), "--library", str(lib)]) == 0
    out, err = capsys.readouterr()
    assert "ended by a crash" in out
    assert f"take {first}: its show died" in err and f"take {second}: its show died and its file" in err
    with Library(lib) as library:
        assert library.get(first)["ticks"] == read_session(cut).ticks
        assert library.get(second)["state"] == "damaged"
        library.begin(cut, read_session(cut).header)  # as a show would leave it again
    assert select(["wide"], str(lib), (".jsonl",)) == [cut.resolve()]
    assert "its show died" in capsys.readouterr().err
    with Library(lib) as library:
        assert library.get(first)["state"] == "crashed"


def test_a_finished_show_completes_the_entry_its_start_made(tmp_path: Path) -> None:
    script = tmp_path / "s.toml"
    script.write_text(SCRIPT.format(speed=0, duration=0.5))
    lib, rec = tmp_path / "takes.db", tmp_path / "show.jsonl"
    r = subprocess.run([sys.executable, "-m", "puppet", "live", "--headless", "--no-panel", "--device",
                        f"mock://{script}", "--record", str(rec), "--library", str(lib), "--tag", "a", "--tag", "b"],
                       capture_output=True, text=True, timeout=180)
    assert r.returncode == 0, r.stderr
    with Library(lib) as library:
        [t] = library.search("")
    assert t["state"] == "complete" and t["duration"] == pytest.approx(0.5) and t["tags"] == ["a", "b"]
    assert t["hash"] == file_hash(rec)[0]


def test_an_overwritten_take_is_reported_and_marked_damaged(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    lib = tmp_path / "takes.db"
    take = write_take(tmp_path / "shoot" / "ana.jsonl", seed=1, performer="ana")
    good = take.read_bytes()
    assert main(["takes", "import", str(take.parent), "--library", str(lib)]) == 0
    capsys.readouterr()
    [known] = takes_json(capsys, lib, "list")
    assert main(["takes", "tag", str(known["id"]), "keeper", "--library", str(lib)]) == 0
    capsys.readouterr()

    take.write_bytes(b"\x00garbage\xff" * 100)
    assert main(["takes", "check", "--no-analyse", "--library", str(lib)]) == 0
    out = capsys.readouterr().out
    assert f"take {known['id']} is damaged" in out and str(take) in out and "0 in place" in out and "1 damaged" in out
    with Library(lib) as library:
        t = library.get(known["id"])
        assert [x["id"] for x in library.search("state:damaged")] == [known["id"]]
    # the entry is marked, its details kept (the take's hash, duration, tags): found again by them
    assert t["state"] == "damaged" and t["hash"] == known["hash"] and t["duration"] == known["duration"]
    assert t["tags"] == ["keeper"]
    assert main(["takes", "list", "--library", str(lib)]) == 0
    assert "[damaged" in capsys.readouterr().out

    # the take restored: in place again, complete
    take.write_bytes(good)
    report = takes_json(capsys, lib, "check", "--no-analyse")
    assert report["ok"] == 1 and report["damaged"] == []
    with Library(lib) as library:
        assert library.get(known["id"])["state"] == "complete"


def test_an_overwritten_take_whose_copy_is_elsewhere_follows_the_copy(tmp_path: Path,
                                                                     capsys: pytest.CaptureFixture) -> None:
    lib = tmp_path / "takes.db"
    take = write_take(tmp_path / "shoot" / "ana.jsonl", seed=1)
    assert main(["takes", "import", str(take), "--library", str(lib)]) == 0
    copy = tmp_path / "backup" / "ana.jsonl"
    copy.parent.mkdir()
    copy.write_bytes(take.read_bytes())
    take.write_text("not a take any more\n")
    report = takes_json(capsys, lib, "check", "--no-analyse", "--in", str(copy.parent))
    assert report["found"] == [[1, str(copy.resolve())]] and report["damaged"] == []
    with Library(lib) as library:
        assert library.get(1)["state"] == "complete" and Path(library.get(1)["path"]) == copy.resolve()


def test_two_shows_recording_at_once_into_one_library(tmp_path: Path) -> None:
    script = tmp_path / "s.toml"
    script.write_text(SCRIPT.format(speed=0, duration=0.5))
    lib = tmp_path / "takes.db"
    procs = [subprocess.Popen([sys.executable, "-m", "puppet", "live", "--headless", "--no-panel", "--device",
                               f"mock://{script}", "--record", str(tmp_path / f"{name}.jsonl"), "--library", str(lib),
                               "--performer", name], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
             for name in ("ana", "bob")]
    for p in procs:
        _, err = p.communicate(timeout=240)
        assert p.returncode == 0, err
    con = sqlite3.connect(lib)
    assert con.execute("PRAGMA integrity_check").fetchone()[0] == "ok"
    con.close()
    with Library(lib) as library:
        rows = {t["performer"]: t for t in library.search("")}
    assert sorted(rows) == ["ana", "bob"]
    for name, t in rows.items():
        assert t["state"] == "complete" and Path(t["path"]).name == f"{name}.jsonl"
        assert t["duration"] == pytest.approx(0.5) and t["hash"] == file_hash(t["path"])[0]


def _killed(take: Path) -> Path:
    """`take` as a show killed mid-recording leaves it: no end record, the last tick cut half way."""
    lines = take.read_text().splitlines(keepends=True)
    assert '"end"' in lines[-1]
    take.write_text("".join(lines[:-1]) + lines[-2][:7])
    return take


def test_a_rebuilt_library_keeps_the_takes_as_they_were_begun(tmp_path: Path) -> None:
    """The journal names a take from its start: a library rebuilt after damage has the take whose
    show died before it ended (read up to its last whole tick), with its performer and tags, and
    every take gets its id back; a crashed take completed by check and moved since is found where
    it went."""
    lib = tmp_path / "takes.db"
    shoot = tmp_path / "shoot"
    a, b, c, d = (shoot / f"{n}.jsonl" for n in "abcd")
    with Library(lib) as library:
        library.begin(a, {"tick_rate": 60.0}, performer="ana", tags=["one"])
        write_take(a, ticks=20, seed=1)
        library.register(a, performer="ana", tags=["one"])
        library.begin(b, {"tick_rate": 60.0}, performer="bob", tags=["wide"])
        _killed(write_take(b, ticks=30, seed=2))
        write_take(c, ticks=25, seed=3)
        library.register(c)
        library.begin(d, {"tick_rate": 60.0}, performer="dee", tags=["moved"])
        _killed(write_take(d, ticks=35, seed=4))
    assert main(["takes", "check", "--no-analyse", "--library", str(lib)]) == 0  # completes b and d
    moved = tmp_path / "elsewhere" / "d.jsonl"
    moved.parent.mkdir()
    d.rename(moved)
    assert main(["takes", "check", "--no-analyse", "--library", str(lib), "--in", str(moved.parent)]) == 0
    with Library(lib) as library:
        before = {t["id"]: (Path(t["path"]).name, t["state"], t["performer"], t["tags"]) for t in library.search("")}
    assert before == {1: ("a.jsonl", "complete", "ana", ["one"]), 2: ("b.jsonl", "crashed", "bob", ["wide"]),
                      3: ("c.jsonl", "complete", "", []), 4: ("d.jsonl", "crashed", "dee", ["moved"])}
    lib.write_bytes(b"not a database any more" * 100)
    warned: list[str] = []
    with Library(lib, warn=warned.append) as library:
        after = {t["id"]: (Path(t["path"]).name, t["state"], t["performer"], t["tags"]) for t in library.search("")}
        assert Path(library.get(4)["path"]) == moved.resolve()
        assert library.get(2)["ticks"] == read_session(b).ticks and not read_session(b).complete
    assert after == before
    assert any("4 registered" in w and "no longer found" not in w for w in warned), warned


def test_a_rebuilt_library_keeps_a_take_whose_show_died_unchecked(tmp_path: Path) -> None:
    lib = tmp_path / "takes.db"
    take = write_take(tmp_path / "shoot" / "cut.jsonl", ticks=30, seed=2)
    s = read_session(_killed(take))
    with Library(lib) as library:
        library.begin(take, s.header, performer="ana", tags=["wide"])
    lib.write_bytes(b"not a database any more" * 100)
    with Library(lib, warn=lambda w: None) as library:
        [t] = library.search("")
    assert t["state"] == "crashed" and t["performer"] == "ana" and t["tags"] == ["wide"]
    assert t["ticks"] == s.ticks and t["hash"] == file_hash(take)[0]


def test_a_library_of_the_first_schema_opens_with_its_takes_complete(tmp_path: Path) -> None:
    from puppet.library import schema

    lib = tmp_path / "takes.db"
    con = sqlite3.connect(lib, isolation_level=None)
    for stmt in schema._statements(schema.MIGRATIONS[0]):
        con.execute(stmt)
    con.execute("INSERT INTO takes (path, hash, size, registered, duration, ticks, tick_rate, performer) "
                "VALUES ('/takes/a.jsonl', 'abc', 10, '2026-12-01', 2.5, 150, 60.0, 'ana')")
    con.execute("PRAGMA user_version = 1")
    con.close()
    with Library(lib) as library:
        [t] = library.search("state:complete")
    assert t["performer"] == "ana" and t["duration"] == 2.5


def test_a_take_overwritten_by_another_take_is_reported_and_re_read(tmp_path: Path,
                                                                   capsys: pytest.CaptureFixture) -> None:
    lib = tmp_path / "takes.db"
    take = write_take(tmp_path / "shoot" / "ana.jsonl", ticks=30, seed=1)
    assert main(["takes", "import", str(take), "--library", str(lib)]) == 0
    write_take(take, ticks=45, seed=3)  # another recording made to the same name
    capsys.readouterr()
    assert main(["takes", "check", "--no-analyse", "--library", str(lib)]) == 0
    out = capsys.readouterr().out
    assert "take 1 changed" in out and "1 changed and re-read" in out
    with Library(lib) as library:
        t = library.get(1)
    assert t["state"] == "complete" and t["ticks"] == 45 and t["hash"] == file_hash(take)[0]


def test_recording_again_after_a_show_died_keeps_the_dead_show_s_take(tmp_path: Path) -> None:
    """A show killed mid-recording, then a show recording to the same file: the killed show's take
    is kept aside as show.1.jsonl and its entry (id, performer, tags) goes with it, completed."""
    script = tmp_path / "s.toml"
    script.write_text(SCRIPT.format(speed=0, duration=0.5))
    lib, rec = tmp_path / "takes.db", tmp_path / "show.jsonl"
    with Library(lib) as library:  # as the killed show left it: begun, never completed
        first = library.begin(rec, {"tick_rate": 60.0}, performer="ana", tags=["first"])
    _killed(write_take(rec, ticks=30, seed=5))
    r = subprocess.run([sys.executable, "-m", "puppet", "live", "--headless", "--no-panel", "--device",
                        f"mock://{script}", "--record", str(rec), "--library", str(lib), "--performer", "bob"],
                       capture_output=True, text=True, timeout=180)
    assert r.returncode == 0, r.stderr
    with Library(lib) as library:
        rows = {Path(t["path"]).name: t for t in library.search("")}
    assert sorted(rows) == ["show.1.jsonl", "show.jsonl"]
    kept = rows["show.1.jsonl"]
    assert kept["id"] == first and kept["performer"] == "ana" and kept["tags"] == ["first"]
    assert kept["state"] == "crashed" and kept["ticks"] == read_session(tmp_path / "show.1.jsonl").ticks
    assert rows["show.jsonl"]["performer"] == "bob" and rows["show.jsonl"]["state"] == "complete"
    assert rows["show.jsonl"]["tags"] == []
