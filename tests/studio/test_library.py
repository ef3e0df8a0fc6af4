"""The take library: registration, search, tags, notes, check (moved and deleted takes), two
writing processes, and damaged library files rebuilt from the takes."""

from __future__ import annotations

import json
import os
import sqlite3
import subprocess
import sys
from pathlib import Path

import pytest

from puppet.cli import main
from puppet.library.store import Library
from takes import write_take

HERE = Path(__file__).resolve().parent


def takes_cli(capsys: pytest.CaptureFixture, lib: Path, *args: str) -> tuple[int, str, str]:
    code = main(["takes", *args, "--library", str(lib)])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture
def folder(tmp_path: Path) -> Path:
    d = tmp_path / "shoot"
    write_take(d / "ana_smile.jsonl", seed=1, performer="ana", markers={10: "good bit"},
               start_time="2026-12-01T10:00:00.000+00:00")
    write_take(d / "ana_brow.jsonl", seed=2, performer="ana", start_time="2026-12-02T10:00:00.000+00:00")
    write_take(d / "day2" / "bob_jaw.jsonl", seed=3, performer="bob", start_time="2026-12-03T10:00:00.000+00:00")
    (d / "notes.jsonl").write_text("this is not a recording\n")
    return d


def test_import_search_tag_note_show(folder: Path, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    lib = tmp_path / "lib" / "takes.db"
    code, out, err = takes_cli(capsys, lib, "import", str(folder))
    assert code == 0 and "registered 3 takes" in out and "notes.jsonl" in err
    code, out, _ = takes_cli(capsys, lib, "list", "--json")
    rows = json.loads(out)
    assert sorted(Path(r["path"]).name for r in rows) == ["ana_brow.jsonl", "ana_smile.jsonl", "bob_jaw.jsonl"]
    by_name = {Path(r["path"]).name: r for r in rows}
    smile = by_name["ana_smile.jsonl"]
    assert smile["performer"] == "ana" and smile["duration"] == pytest.approx(0.5)
    assert smile["markers"] == [[pytest.approx(10 / 60, abs=1e-4), "good bit"]]
    assert smile["devices"] == ["mock://studio"] and smile["face"] == "procedural" and len(smile["hash"]) == 64

    def ids(query: str) -> list[str]:
        code, out, _ = takes_cli(capsys, lib, "search", query, "--json")
        assert code == 0
        return sorted(Path(r["path"]).name for r in json.loads(out))

    assert ids("performer:ana") == ["ana_brow.jsonl", "ana_smile.jsonl"]
    assert ids("date:2026-12-03") == ["bob_jaw.jsonl"]
    assert ids("after:2026-12-02") == ["ana_brow.jsonl", "bob_jaw.jsonl"]
    for bad in ("date:2026-13", "after:yesterday", "before:2026-02-30"):  # not "no takes": say why
        code, out, err = takes_cli(capsys, lib, "search", bad)
        assert code == 2 and err.count("\n") == 1 and bad in err and "YYYY-MM-DD" in err, (bad, err)
    assert ids("smil") == ["ana_smile.jsonl"]  # a word's start matches the name
    assert ids("good") == ["ana_smile.jsonl"]  # marker labels are searched
    assert takes_cli(capsys, lib, "tag", str(smile["id"]), "Keeper")[0] == 0
    assert takes_cli(capsys, lib, "note", str(by_name["bob_jaw.jsonl"]["id"]), "jaw pops at the end")[0] == 0
    assert ids("tag:keeper") == ["ana_smile.jsonl"]
    assert ids("pops") == ["bob_jaw.jsonl"] and ids("pops performer:ana") == []
    code, out, _ = takes_cli(capsys, lib, "show", str(smile["id"]))
    assert "keeper" in out and "good bit" in out and "ana" in out
    code, _, err = takes_cli(capsys, lib, "show", "999")
    assert code == 2 and "no take 999" in err


def test_a_take_is_found_by_the_face_named_when_it_was_recorded(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """`face:NAME` searched the rig's name: every character of the scanned head was "ict" and the
    procedural face "default" (no longer the default face), so `face:bob` for a take recorded with
    `--face bob` and `face:procedural` found nothing. The library keeps the face as --face named it."""
    shoot = tmp_path / "shoot"
    plain = write_take(shoot / "plain.jsonl", ticks=6)  # the procedural face
    lines = plain.read_text().splitlines(keepends=True)
    head = json.loads(lines[0])
    head["rig"] = {"name": "ict", "hash": "0123456789abcdef", "path": None, "face": "bob",
                   "identity": [0.5] * 100, "identity_hash": "fedcba9876543210"}
    (shoot / "second.jsonl").write_text(json.dumps(head) + "\n" + "".join(lines[1:]))
    lib = tmp_path / "lib" / "takes.db"
    assert takes_cli(capsys, lib, "import", str(shoot))[0] == 0

    def found(query: str) -> list[str]:
        code, out, _ = takes_cli(capsys, lib, "search", query, "--json")
        assert code == 0
        return sorted(Path(r["path"]).name for r in json.loads(out))

    assert found("face:bob") == ["second.jsonl"]
    assert found("face:procedural") == ["plain.jsonl"]
    assert found("bob") == ["second.jsonl"]  # the words search the face too


def test_expression_search_after_check(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    lib = tmp_path / "takes.db"
    take = write_take(tmp_path / "s" / "happy.jsonl", ticks=40, seed=5)
    takes_cli(capsys, lib, "import", str(tmp_path / "s"))
    code, out, _ = takes_cli(capsys, lib, "check")
    assert code == 0 and "analysed 1" in out
    t = json.loads(takes_cli(capsys, lib, "show", "1", "--json")[1])
    assert t["thumbnail"] and t["expressions"], t
    from puppet.cli import main as puppet

    assert puppet(["recognize", str(take), "--json"]) == 0
    spans = json.loads(capsys.readouterr().out)
    assert [e["expression"] for e in t["expressions"]] == [s["expression"] for s in spans]
    found = json.loads(takes_cli(capsys, lib, "search", f"expression:{spans[-1]['expression']}", "--json")[1])
    assert [r["id"] for r in found] == [1]
    assert takes_cli(capsys, lib, "show", "1", "--thumbnail", str(tmp_path / "t.png"))[0] == 0
    assert (tmp_path / "t.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_check_finds_moved_takes_and_marks_deleted(folder: Path, tmp_path: Path,
                                                   capsys: pytest.CaptureFixture) -> None:
    lib = tmp_path / "takes.db"
    takes_cli(capsys, lib, "import", str(folder))
    (folder / "archive").mkdir()
    os.replace(folder / "ana_smile.jsonl", folder / "archive" / "renamed.jsonl")
    (folder / "ana_brow.jsonl").unlink()
    code, out, _ = takes_cli(capsys, lib, "check", "--no-analyse")
    assert code == 0 and "1 found again" in out and "1 missing" in out
    rows = {r["id"]: r for r in json.loads(takes_cli(capsys, lib, "list", "--json")[1])}
    paths = {Path(r["path"]).name: r["missing"] for r in rows.values()}
    assert paths == {"renamed.jsonl": 0, "ana_brow.jsonl": 1, "bob_jaw.jsonl": 0}
    assert [Path(r["path"]).name for r in json.loads(takes_cli(capsys, lib, "search", "missing:yes", "--json")[1])] \
        == ["ana_brow.jsonl"]
    # --in naming no folder is one line, exit 2 (not a check that silently looked nowhere)
    code, out, err = takes_cli(capsys, lib, "check", "--no-analyse", "--in", str(tmp_path / "no-such"))
    assert code == 2 and err.count("\n") == 1 and "no-such: not a folder" in err


def test_import_one_recording(folder: Path, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    lib = tmp_path / "takes.db"
    code, out, _ = takes_cli(capsys, lib, "import", str(folder / "day2" / "bob_jaw.jsonl"))
    assert code == 0 and "registered 1 take " in out
    assert [Path(r["path"]).name for r in json.loads(takes_cli(capsys, lib, "list", "--json")[1])] == ["bob_jaw.jsonl"]
    code, _, err = takes_cli(capsys, lib, "import", str(folder / "notes.jsonl"))  # not a recording: said why
    assert code == 0 and "notes.jsonl" in err
    code, _, err = takes_cli(capsys, lib, "import", str(tmp_path / "gone.jsonl"))
    assert code == 2 and "no such folder or recording" in err



def test_import_skips_a_pipe_named_like_a_take_instead_of_waiting_for_it(folder: Path, tmp_path: Path) -> None:
    """A FIFO `x.jsonl` in the folder (a script's leftover): opening it waited forever for a writer."""
    os.mkfifo(folder / "day2" / "pipe.jsonl")
    lib = tmp_path / "takes.db"
    run = [sys.executable, "-m", "puppet", "takes", "--library", str(lib), "import"]
    r = subprocess.run([*run, str(folder)], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0 and "pipe.jsonl: not a regular file" in r.stderr, r.stderr
    assert "registered" in r.stdout
    r = subprocess.run([*run, str(folder / "day2" / "pipe.jsonl")], capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and "pipe.jsonl: not a regular file" in r.stderr, r.stderr


WRITER = """
import sys
sys.path.insert(0, {here!r})
from pathlib import Path
from puppet.library.store import Library
from takes import write_take
lib = Library(sys.argv[1])
name = sys.argv[2]
for k in range(int(sys.argv[3])):
    p = Path(sys.argv[4]) / f"{{name}}_{{k}}.jsonl"
    lib.begin(p, {{"performer": name, "tick_rate": 60.0}}, tags=["live-" + name])  # as a show starts
    write_take(p, ticks=5, seed=k, performer=name)
    i = lib.register(p)
    lib.tag(i, "batch-" + name)
    lib.tag(1, name + str(k))
"""


def test_two_writing_processes(tmp_path: Path) -> None:
    lib_path = tmp_path / "takes.db"
    first = write_take(tmp_path / "first.jsonl", ticks=5)
    with Library(lib_path) as lib:
        assert lib.register(first) == 1
    n = 25
    procs = [subprocess.Popen([sys.executable, "-c", WRITER.format(here=str(HERE)), str(lib_path), name, str(n),
                               str(tmp_path / name)], stderr=subprocess.PIPE, text=True)
             for name in ("ana", "bob")]
    for p in procs:
        _, err = p.communicate(timeout=240)
        assert p.returncode == 0, err
    con = sqlite3.connect(lib_path)
    assert con.execute("PRAGMA integrity_check").fetchone()[0] == "ok"
    assert con.execute("SELECT count(*) FROM takes").fetchone()[0] == 2 * n + 1
    assert con.execute("SELECT count(*) FROM tags WHERE take_id = 1").fetchone()[0] == 2 * n
    assert con.execute("SELECT count(*) FROM takes WHERE state != 'complete'").fetchone()[0] == 0
    with Library(lib_path) as lib:
        assert len(lib.search("performer:ana tag:batch-ana tag:live-ana")) == n
        assert len(lib.search("bob")) == n + 1  # bob's takes and take 1, tagged bob0..bob24


def _damaged_variants(good: bytes) -> dict[str, bytes]:
    """Damage as disks and scripts do it, generated from the good file with a fixed seed."""
    import random

    rng = random.Random(22)
    page = 4096
    out: dict[str, bytes] = {"empty": b"", "text": b"takes: none\n" * 40, "utf16": "takes".encode("utf-16") * 50}
    for cut in (50, 100, page, len(good) // 2, len(good) - 1):
        out[f"cut-{cut}"] = good[:cut]
    out["header-garbage"] = bytes(rng.randrange(256) for _ in range(100)) + good[100:]
    for k in range(1, len(good) // page):
        b = bytearray(good)
        b[k * page:(k + 1) * page] = bytes(page)
        out[f"page-{k}-zeroed"] = bytes(b)
    for k in range(3):
        b = bytearray(good)
        at = rng.randrange(page, len(good)) // page * page  # a page's b-tree header
        for off in range(0, 8):
            b[at + off] ^= 0xFF
        out[f"btree-header-{k}"] = bytes(b)
    return out


def test_damaged_library_is_one_line_and_rebuilt(folder: Path, tmp_path: Path,
                                                 capsys: pytest.CaptureFixture) -> None:
    lib = tmp_path / "good" / "takes.db"
    takes_cli(capsys, lib, "import", str(folder))
    smile = next(r for r in json.loads(takes_cli(capsys, lib, "list", "--json")[1]) if "smile" in r["path"])
    takes_cli(capsys, lib, "tag", str(smile["id"]), "keeper")
    takes_cli(capsys, lib, "note", str(smile["id"]), "the one")
    con = sqlite3.connect(lib)
    con.execute("PRAGMA wal_checkpoint(TRUNCATE)")
    con.close()
    good = lib.read_bytes()
    want = sorted(r["path"] for r in json.loads(takes_cli(capsys, lib, "list", "--json")[1]))
    rebuilt = 0
    for name, data in _damaged_variants(good).items():
        d = tmp_path / name
        d.mkdir()
        (d / "takes.db").write_bytes(data)
        (d / "takes.db.journal").write_bytes((lib.parent / "takes.db.journal").read_bytes())
        code, out, err = takes_cli(capsys, d / "takes.db", "list", "--json")
        lines = err.strip().splitlines()
        assert code == 0 and len(lines) <= 1, (name, [x[:60] for x in lines])
        assert sorted(r["path"] for r in json.loads(out)) == want, name
        if lines:
            rebuilt += 1
            assert "damaged" in lines[0] and str(d / "takes.db") in lines[0] and len(lines[0]) < 400, name
            keeper = json.loads(takes_cli(capsys, d / "takes.db", "search", "tag:keeper", "--json")[1])
            assert [r["notes"] for r in keeper] == ["the one"], name
            assert name == "empty" or list(d.glob("takes.db.damaged-*")), name  # the damaged file is kept
            # the rebuilt file is whole: a second run says nothing
            assert takes_cli(capsys, d / "takes.db", "list")[2] == "", name
    assert rebuilt >= 8


def test_reimport_adds_nothing_and_a_rebuild_keeps_the_ids(folder: Path, tmp_path: Path,
                                                             capsys: pytest.CaptureFixture) -> None:
    """Importing a folder again registers nothing twice and says so; a take registered again (a
    show continuing it) keeps its id, and so does every take when a damaged library is rebuilt:
    `puppet takes show 2` is the same take before and after."""
    lib = tmp_path / "lib" / "takes.db"
    assert "registered 3 takes" in takes_cli(capsys, lib, "import", str(folder))[1]
    journal = (lib.parent / "takes.db.journal").read_bytes()
    code, out, _ = takes_cli(capsys, lib, "import", str(folder))
    assert code == 0 and "registered 0 takes" in out and "3 already in the library" in out
    assert (lib.parent / "takes.db.journal").read_bytes() == journal
    write_take(folder / "later.jsonl", seed=4, performer="cy", start_time="2026-12-04T10:00:00.000+00:00")
    code, out, _ = takes_cli(capsys, lib, "import", str(folder))
    assert "registered 1 take from" in out and "3 already" in out
    first = min(json.loads(takes_cli(capsys, lib, "list", "--json")[1]), key=lambda r: r["id"])
    with Library(lib) as store:
        store.register(first["path"])
    before = {r["path"]: r["id"] for r in json.loads(takes_cli(capsys, lib, "list", "--json")[1])}
    assert sorted(before.values()) == [1, 2, 3, 4]
    lib.write_bytes(b"not a database" * 100)
    for extra in lib.parent.glob("takes.db-*"):
        extra.unlink()
    code, out, err = takes_cli(capsys, lib, "list", "--json")
    assert code == 0 and "damaged" in err
    assert {r["path"]: r["id"] for r in json.loads(out)} == before


def test_live_recording_is_registered(tmp_path: Path) -> None:
    script = tmp_path / "s.toml"
    script.write_text('impersonate = "sgi"\nspeed = 0\nduration = 0.5\n[[ramp]]\ncontrol = "dial1"\n'
                      'start = 0.0\nduration = 0.4\nfrom = 0.0\nto = 1.0\nrate = 50\n')
    lib = tmp_path / "takes.db"
    rec = tmp_path / "show.jsonl"
    r = subprocess.run([sys.executable, "-m", "puppet", "live", "--headless", "--no-panel", "--device",
                        f"mock://{script}", "--record", str(rec), "--performer", "Ana Lopez", "--library", str(lib)],
                       capture_output=True, text=True, timeout=180)
    assert r.returncode == 0, r.stderr
    with Library(lib) as library:
        rows = library.search('performer:"ana lopez"')
        assert [Path(t["path"]) for t in rows] == [rec.resolve()]
        assert rows[0]["devices"] == [f"mock://{script}"] and rows[0]["duration"] == pytest.approx(0.5)


def test_library_option_before_the_action_and_env(folder: Path, tmp_path: Path, capsys: pytest.CaptureFixture,
                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    lib = tmp_path / "a.db"
    assert main(["takes", "--library", str(lib), "import", str(folder)]) == 0
    assert main(["takes", "--library", str(lib), "search", "performer:bob", "--json"]) == 0
    capsys.readouterr()
    monkeypatch.setenv("PUPPET_LIBRARY", str(lib))
    assert main(["takes", "search", "performer:bob", "--json"]) == 0
    assert [Path(r["path"]).name for r in json.loads(capsys.readouterr().out)] == ["bob_jaw.jsonl"]
    monkeypatch.setenv("PUPPET_LIBRARY", "off")
    assert main(["takes", "list"]) == 2 and "PUPPET_LIBRARY=off" in capsys.readouterr().err


def test_a_file_that_was_never_a_library_is_left_alone(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """`--library` naming some other file by mistake (a text file, another program's database) is
    one line and exit 2, and the file stays as it was: only a library whose journal names takes is
    moved aside and rebuilt."""
    text = tmp_path / "accounts.txt"
    text.write_text("root:x:0:0:root:/root:/bin/bash\n")
    other = tmp_path / "other.sqlite"
    con = sqlite3.connect(other)
    con.execute("CREATE TABLE notes (id INTEGER PRIMARY KEY, body TEXT)")
    con.execute("INSERT INTO notes (body) VALUES ('keep me')")
    con.commit()
    con.close()
    for path in (text, other):
        before = path.read_bytes()
        code, out, err = takes_cli(capsys, path, "list")
        assert code == 2 and out == "", (path, out)
        assert len(err.strip().splitlines()) == 1 and str(path) in err and "Traceback" not in err, err
        assert path.read_bytes() == before
        assert sorted(p.name for p in tmp_path.iterdir() if p.name.startswith(path.name)) == [path.name], path


def test_a_folder_given_as_the_library_says_so(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """`--library DIR` said "cannot open the take library: unable to open database file"; it says
    the name is a folder and which file to name instead, and the folder is left as it was."""
    code, out, err = takes_cli(capsys, tmp_path, "list")
    assert code == 2 and out == ""
    assert len(err.strip().splitlines()) == 1 and "is a folder" in err and str(tmp_path / "takes.db") in err, err
    assert list(tmp_path.iterdir()) == []


def test_recording_again_to_a_take_keeps_its_tags_with_the_kept_take(tmp_path: Path) -> None:
    """Recording to a path that holds a take keeps the earlier take as NAME.1.jsonl: the library
    follows it there (its id, tags and notes), and the new recording is a take of its own."""
    script = tmp_path / "s.toml"
    script.write_text('impersonate = "sgi"\nspeed = 0\nduration = 0.5\n[[ramp]]\ncontrol = "dial1"\n'
                      'start = 0.0\nduration = 0.4\nfrom = 0.0\nto = 1.0\nrate = 50\n')
    lib, rec = tmp_path / "takes.db", tmp_path / "show.jsonl"
    cmd = [sys.executable, "-m", "puppet", "live", "--headless", "--no-panel", "--device", f"mock://{script}",
           "--record", str(rec), "--library", str(lib)]
    assert subprocess.run(cmd + ["--performer", "ana"], capture_output=True, timeout=180).returncode == 0
    with Library(lib) as library:
        first = library.search("")[0]["id"]
        library.tag(first, "keeper")
        library.note(first, "the good one")
    assert subprocess.run(cmd + ["--performer", "bob"], capture_output=True, timeout=180).returncode == 0
    kept = tmp_path / "show.1.jsonl"
    assert kept.is_file()
    with Library(lib) as library:
        rows = {Path(t["path"]).name: t for t in library.search("")}
        assert sorted(rows) == ["show.1.jsonl", "show.jsonl"]
        assert rows["show.1.jsonl"]["id"] == first and rows["show.1.jsonl"]["tags"] == ["keeper"]
        assert rows["show.1.jsonl"]["notes"] == "the good one" and rows["show.1.jsonl"]["performer"] == "ana"
        assert rows["show.jsonl"]["tags"] == [] and rows["show.jsonl"]["performer"] == "bob"


def test_the_listing_keeps_its_columns_however_long_a_cell(folder: Path, tmp_path: Path,
                                                           capsys: pytest.CaptureFixture) -> None:
    lib = tmp_path / "takes.db"
    with Library(lib) as library:
        first = library.register(folder / "ana_smile.jsonl", performer="Anastasia Lopez-Villanueva")
        library.register(folder / "ana_brow.jsonl")
        library.set_spans(library.get(first)["hash"], [(0.0, 0.2, "happiness", 0.9), (0.2, 0.4, "sadness", 0.8),
                                                       (0.4, 0.5, "surprise", 0.9)])
    code, out, _ = takes_cli(capsys, lib, "list")
    lines = out.splitlines()
    assert code == 0 and len(lines) == 3 and "happiness,sadness,surprise" in out, out
    column = lines[0].index("path")
    assert all(line[column:].startswith(str(folder)) for line in lines[1:]), out


def test_two_imports_at_once_count_each_take_once(folder: Path, tmp_path: Path,
                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    """Two `takes import` of one folder into one library at once: a take the other import
    registered after this one looked was counted 'registered' by both (their counts added up to
    more takes than the folder holds). Here the other import registers every take between this one's look and its write: this
    one reports them all as already in the library, unchanged."""
    from puppet.library.upkeep import import_folder

    lib_path = tmp_path / "takes.db"
    lib, other = Library(lib_path), Library(lib_path)
    real = Library.register

    def other_first(self: Library, path: str | Path, *args: object, **kwargs: object) -> int:
        if self is lib:
            real(other, path)
        return real(self, path, *args, **kwargs)

    monkeypatch.setattr(Library, "register", other_first)
    rep = import_folder(lib, folder)
    assert rep.registered == [] and len(rep.known) == 3
    monkeypatch.setattr(Library, "register", real)
    fresh = import_folder(Library(tmp_path / "fresh.db"), folder)
    assert len(fresh.registered) == 3 and fresh.known == []


def test_a_take_id_past_64_bits_is_no_take(folder: Path, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """`puppet takes show 99999999999999999999999` (a pasted number, a page's URL): SQLite's
    OverflowError was a traceback (the page's take routes answered 500 with it on the show's
    terminal). It is 'no take N', one line, exit 2, like any id the library does not hold."""
    lib = tmp_path / "takes.db"
    assert takes_cli(capsys, lib, "import", str(folder))[0] == 0
    huge = str(1 << 80)
    for args in (("show", huge), ("tag", huge, "keep"), ("note", huge, "text"), ("show", str(-(1 << 70)))):
        code, out, err = takes_cli(capsys, lib, *args)
        assert code == 2 and err.count("\n") == 1 and f"no take {args[1]}" in err, (args, err)


@pytest.mark.parametrize("args", [["tag", "1", "keeper"], ["note", "1", "a note"], ["import", "TAKE"]])
def test_a_library_that_cannot_be_written_is_one_line(folder: Path, tmp_path: Path, args: list[str],
                                                      capsys: pytest.CaptureFixture,
                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    """A library on a read-only file or file system: `takes tag` and `takes note` were an
    sqlite3.OperationalError traceback, and `takes import` counted each take as "not a
    recording". Each is one line naming the library, exit 2, and the library is as it was."""
    from puppet.library import schema

    lib = tmp_path / "lib" / "takes.db"
    with Library(lib) as library:
        library.register(folder / "ana_smile.jsonl")
    before = takes_cli(capsys, lib, "list", "--json")[1]
    connect = schema.connect

    def read_only(path: Path):  # what SQLite answers for a file it may not write
        con, new = connect(path)
        con.execute("PRAGMA query_only = ON")
        return con, new

    monkeypatch.setattr(schema, "connect", read_only)
    args = [str(folder / "ana_brow.jsonl") if a == "TAKE" else a for a in args]
    code, out, err = takes_cli(capsys, lib, *args)
    assert code == 2 and err.count("\n") == 1 and err.startswith(f"puppet: error: {lib}: "), err
    assert "read-only" in err and "--library" in err
    monkeypatch.setattr(schema, "connect", connect)
    assert takes_cli(capsys, lib, "list", "--json")[1] == before


def test_reading_a_library_that_is_not_there_makes_nothing(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """`puppet takes list --library` with a mistyped path made its folders and an empty library
    there; reading makes nothing: list and search find no takes, show names the missing library."""
    lib = tmp_path / "typo" / "deeper" / "takes.db"
    code, out, _ = takes_cli(capsys, lib, "list")
    assert code == 0 and "no takes" in out and str(lib) in out
    assert takes_cli(capsys, lib, "search", "smile", "--json")[:2] == (0, "[]\n")
    code, _, err = takes_cli(capsys, lib, "show", "1")
    assert code == 2 and str(lib) in err and err.count("\n") == 1
    assert not (tmp_path / "typo").exists()


@pytest.mark.parametrize("query", ["id:99999999999999999999999", "id:\u00b2"])
def test_an_id_no_take_can_have_finds_nothing(folder: Path, tmp_path: Path, query: str,
                                              capsys: pytest.CaptureFixture) -> None:
    """An id past SQLite's 64-bit integers was an OverflowError traceback (and a 500 on the page's
    take search), a superscript digit a ValueError from int()."""
    lib = tmp_path / "lib" / "takes.db"
    with Library(lib) as library:
        library.register(folder / "ana_smile.jsonl")
    code, out, err = takes_cli(capsys, lib, "search", query, "--json")
    assert (code, out) == (0, "[]\n"), err


def test_a_library_in_a_folder_that_cannot_be_written_is_read(folder: Path, tmp_path: Path,
                                                              capsys: pytest.CaptureFixture,
                                                              monkeypatch: pytest.MonkeyPatch) -> None:
    """A library on a read-only file system or share (SQLite cannot make its -shm file beside it)
    was called damaged and could not even be listed. It is read as it is; a change to it is one
    line saying it is read-only, and nothing is written beside it."""
    d = tmp_path / "shared"
    lib = d / "takes.db"
    with Library(lib) as library:
        library.tag(library.register(folder / "ana_smile.jsonl"), "keeper")
    before = sorted(p.name for p in d.iterdir())
    d.chmod(0o555)
    try:
        if os.access(d, os.W_OK):  # the superuser writes anyway: the folder as access(2) sees it on a read-only mount
            real = os.access
            monkeypatch.setattr(os, "access", lambda p, m, **kw: False if (Path(p) == d and m & os.W_OK) else real(p, m, **kw))
        code, out, err = takes_cli(capsys, lib, "search", "keeper", "--json")
        assert code == 0 and [t["path"] for t in json.loads(out)] == [str(folder / "ana_smile.jsonl")], err
        code, _, err = takes_cli(capsys, lib, "tag", "1", "other")
        assert code == 2 and "read-only" in err and err.count("\n") == 1, err
    finally:
        d.chmod(0o755)
    assert sorted(p.name for p in d.iterdir()) == before


def test_a_filter_value_the_library_does_not_know_is_one_line(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """`state:crash` (for crashed) matched nothing and `missing:maybe` was taken as no, without a
    word: the user read 'no takes' as an answer. Now one line names what the filter takes, exit 2."""
    lib = tmp_path / "takes.db"
    write_take(tmp_path / "a.jsonl", seed=3)
    assert main(["takes", "--library", str(lib), "import", str(tmp_path)]) == 0
    capsys.readouterr()
    for query, says in (("state:crash", "complete, recording, crashed, damaged"), ("missing:maybe", "yes or no")):
        assert main(["takes", "--library", str(lib), "search", query]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and query in err and says in err, err
    assert main(["takes", "--library", str(lib), "search", "state:Complete missing:no"]) == 0
    assert "a.jsonl" in capsys.readouterr().out
