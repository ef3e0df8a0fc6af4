"""Keeping the library true to the disk: importing a folder of takes, checking that every take is
still where the library says (finding moved ones again by content hash), and the slower analysis
of a take (a thumbnail and the expression spans `puppet recognize` finds), which `puppet takes
check` makes for every take that lacks it, so recording a show never waits for it."""

from __future__ import annotations

import argparse
import io
import os
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from puppet.errors import ConfigError, PuppetError
from puppet.library.schema import LibraryUnwritable
from puppet.library.store import Library, find_by_hash
from puppet.library.takeinfo import file_hash

THUMB_SIZE = (256, 144)


@dataclass
class ImportReport:
    registered: list[int] = field(default_factory=list)
    skipped: list[str] = field(default_factory=list)  # "FILE: why"
    known: list[int] = field(default_factory=list)  # already registered there, unchanged


def import_folder(lib: Library, folder: str | Path, performer: str | None = None) -> ImportReport:
    """Register every recording (`*.jsonl`) under `folder` (or the one recording `folder` names);
    other files are skipped with the reason."""
    root = Path(folder)
    if root.is_file():
        files = [root]
    elif root.is_dir():
        files = sorted(p for p in root.rglob("*.jsonl")
                       if not any(part.startswith(".") for part in p.relative_to(root).parts))
    elif root.exists():
        raise PuppetError(f"{folder}: not a regular file (a pipe or a device); save the recording as a file")
    else:
        raise PuppetError(f"{folder}: no such folder or recording")
    rep = ImportReport()
    from puppet.session import _being_recorded

    for p in files:
        if not p.is_file():  # a pipe named like a take would wait forever for a writer
            rep.skipped.append(f"{p}: not a regular file (a folder, a pipe or a device)")
            continue
        if _being_recorded(p):
            rep.skipped.append(f"{p}: a show is recording it now; its library registers it (import it again "
                               "when the show is over for another library)")
            continue
        try:
            row = lib.con.execute("SELECT id, hash, size FROM takes WHERE path = ? AND missing = 0",
                                  (str(p.resolve()),)).fetchone()
            if row is not None and performer is None and p.stat().st_size == row[2] and file_hash(p)[0] == row[1]:
                rep.known.append(int(row[0]))  # nothing new: no second registration in the journal
                continue
            known = len(rep.known)  # another import may have registered it since the look above
            take_id = lib.register(p, performer=performer, unchanged=rep.known if performer is None else None)
            if len(rep.known) == known:
                rep.registered.append(take_id)
        except LibraryUnwritable:
            raise  # the library's fault, not the file's: the import stops with that one line
        except (ConfigError, PuppetError) as err:
            rep.skipped.append(str(err))
    return rep


@dataclass
class CheckReport:
    ok: int = 0
    changed: list[int] = field(default_factory=list)
    found: list[tuple[int, str]] = field(default_factory=list)  # moved: found again at
    missing: list[int] = field(default_factory=list)
    analysed: list[int] = field(default_factory=list)
    failed: list[str] = field(default_factory=list)
    crashed: list[int] = field(default_factory=list)  # its show died: completed from what the file holds
    recording: list[int] = field(default_factory=list)  # a show is recording it now: left to the show
    damaged: list[tuple[int, str]] = field(default_factory=list)  # no longer a take: why

    @property
    def checked(self) -> int:
        return (self.ok + len(self.changed) + len(self.found) + len(self.missing) + len(self.crashed)
                + len(self.recording) + len(self.damaged))


def check(lib: Library, roots: list[Path] | None = None, analyse: bool = True,
          progress: Callable[[str], None] | None = None) -> CheckReport:
    """Every take: present and unchanged, changed (re-read), moved (found again by hash under the
    folders of the library's takes and `roots`) or missing (marked); then analyse takes lacking it."""
    rep = CheckReport()
    rows = [lib.get(i) for i in lib.all_ids()]
    search = list(roots or []) + sorted({Path(r["path"]).parent for r in rows})
    # search the nearest existing ancestors too: a take moved to a sibling folder is found
    extra = {p.parent for p in search if p.parent != p}
    search += sorted(e for e in extra if e.is_dir() and e != Path("/"))
    for r in rows:
        p = Path(r["path"])
        if r["state"] == "recording":  # its show is still at it
            rep.recording.append(r["id"])
            continue
        if r["state"] == "died" and p.is_file():  # its show was killed: the take holds its last whole tick
            _complete(lib, rep, r)
            continue
        if p.is_file():
            try:
                digest, size = file_hash(p)
            except ConfigError as err:
                rep.failed.append(str(err))
                continue
            if digest != r["hash"] or r["state"] == "damaged":
                try:
                    lib.register(p)
                except (ConfigError, PuppetError) as err:
                    again = find_by_hash(r["hash"], r["size"], [d for d in search if d.is_dir()]) if r["hash"] else None
                    if again is not None:  # the take itself is elsewhere: the entry follows it
                        lib.set_place(r["id"], again, False)
                        lib.set_state(r["id"], "complete" if r["state"] == "damaged" else r["state"])
                        rep.found.append((r["id"], again))
                    else:
                        _damaged(lib, rep, r, err)
                    continue
                if digest == r["hash"]:
                    rep.ok += 1  # a damaged take's file holds the take again
                else:
                    rep.changed.append(r["id"])
            else:
                rep.ok += 1
                if r["missing"]:
                    lib.set_place(r["id"], None, False)
            continue
        again = find_by_hash(r["hash"], r["size"], [d for d in search if d.is_dir()]) if r["hash"] else None
        if again is not None:
            lib.set_place(r["id"], again, False)
            rep.found.append((r["id"], again))
        else:
            lib.set_place(r["id"], None, True)
            rep.missing.append(r["id"])
    if analyse:
        for i in lib.all_ids():
            r = lib.get(i)
            if r["analysed"] or r["missing"] or r["state"] in ("recording", "died", "damaged"):
                continue
            if progress:
                progress(f"analysing take {i} ({Path(r['path']).name})")
            try:
                thumb, spans = analyse_take(r["path"])
            except (ConfigError, PuppetError) as err:
                rep.failed.append(str(err))
                continue
            lib.set_analysis(i, r["hash"], thumb, spans)
            rep.analysed.append(i)
    return rep


def complete_died(lib: Library) -> CheckReport:
    """Complete the entries of the takes whose show died while recording them (read up to their
    last whole tick: state `crashed`; a file that no longer holds the take: `damaged`), as `check`
    does, so a listing never waits for a `takes check` by hand. Takes being recorded are left to
    their shows. A library that cannot be written to leaves them as they are."""
    import sqlite3

    rep = CheckReport()
    ids = [r[0] for r in lib.con.execute("SELECT id FROM takes WHERE state = 'recording'")]
    warn, lib.warn = lib.warn, lambda s: None  # the reader's "no end record" is what completing says
    try:
        for i in ids:
            r = lib.get(i)
            if r["state"] == "died" and Path(r["path"]).is_file():
                _complete(lib, rep, r)
    except (sqlite3.Error, OSError, ConfigError):  # a library that cannot be written is still listed
        pass
    finally:
        lib.warn = warn
    return rep


def _complete(lib: Library, rep: CheckReport, r: dict) -> None:
    """A take whose show died: its entry completed from what its file holds, or marked damaged."""
    try:
        lib.register(Path(r["path"]))
        rep.crashed.append(r["id"])
    except (ConfigError, PuppetError) as err:
        _damaged(lib, rep, r, err)


def _damaged(lib: Library, rep: CheckReport, r: dict, err: Exception) -> None:
    """The file at the take's place no longer holds a take: the entry keeps its details, tags and
    notes (the take is found again by its hash if it turns up) and is marked `damaged`."""
    lib.set_state(r["id"], "damaged")
    rep.damaged.append((r["id"], str(err)))


def thumbnail(path: str | Path) -> bytes | None:
    """A small PNG of the take's middle frame (None when no OpenGL is available: the rest of the
    analysis still counts)."""
    from puppet.replay import Replayer, build_performance
    from puppet.session import read_session

    perf = build_performance(read_session(path), None)
    rp = Replayer(perf)
    rp.seek(perf.ticks // 2)
    try:
        from PIL import Image

        from render.offscreen import OffscreenRenderer

        with OffscreenRenderer(perf.face.model, THUMB_SIZE) as r:
            img = r.render_frame(rp.state)
    except Exception:  # no EGL here: a take without a picture
        return None
    buf = io.BytesIO()
    Image.fromarray(img).save(buf, "PNG", optimize=True)
    return buf.getvalue()


def expression_spans(path: str | Path) -> list[tuple[float, float, str, float]]:
    """(start, end, expression, score) per span: what `puppet recognize TAKE` prints."""
    from puppet.cmd_recognize import analyse

    spans, _ = analyse(argparse.Namespace(input=str(path), rig=None, map=None, fps=None))
    return [(float(s.start), float(s.end), str(s.expression), float(s.scores.get(s.expression, 0.0)))
            for s in spans]


def analyse_take(path: str | Path) -> tuple[bytes | None, list[tuple[float, float, str, float]]]:
    if not os.path.isfile(path):
        raise ConfigError(f"{path}: the take is missing")
    return thumbnail(path), expression_spans(path)
