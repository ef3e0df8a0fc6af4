"""The take library: register, find, tag, annotate and check takes (SQLite, see schema.py).

Beside the database lives its journal, `NAME.journal`: one JSON line per registration, tag, note
or move, appended with a single O_APPEND write. The database is the index; the takes themselves
and the journal are the truth. A damaged database is moved aside and rebuilt by re-reading every
take the journal names (its tags and notes follow the take's content hash), with one warning line."""

from __future__ import annotations

import datetime as _dt
import fcntl
import json
import os
import shlex
import socket
import sqlite3
import sys
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

from puppet.errors import ConfigError, PuppetError
from puppet.library import schema
from puppet.library.takeinfo import TakeInfo, file_hash, header_fields, read_take_info

MAX_TAG = 64
MAX_NOTE = 4000
ENV = "PUPPET_LIBRARY"


def default_path() -> Path | None:
    """$PUPPET_LIBRARY (`off`: no library), else $XDG_DATA_HOME/facepuppet/takes.db, else
    ~/.local/share/facepuppet/takes.db."""
    env = os.environ.get(ENV)
    if env:
        return None if env.lower() == "off" else Path(env)
    base = os.environ.get("XDG_DATA_HOME") or str(Path.home() / ".local" / "share")
    return Path(base) / "facepuppet" / "takes.db"


def _warn(text: str) -> None:
    print(f"puppet: warning: {text}", file=sys.stderr)


def _now() -> str:
    return _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")


def clean_tag(tag: str) -> str:
    t = " ".join(str(tag).split()).lower()
    if not t or len(t) > MAX_TAG:
        raise PuppetError(f"a tag is 1 to {MAX_TAG} characters, got {tag!r:.80}")
    return t


#: the states a `state:` filter takes (died: a show killed while recording, stored as recording)
QUERY_STATES = ("complete", "recording", "crashed", "damaged", "died")

class Library:
    """One open library file. Every method is one transaction; safe with other processes writing."""

    def __init__(self, path: str | Path, warn: Callable[[str], None] = _warn) -> None:
        self.path = Path(path)
        self.journal = self.path.with_name(self.path.name + ".journal")
        self.warn = warn
        try:
            self.con, new = schema.connect(self.path)
        except schema.LibraryDamaged as err:
            if not self._journaled():  # never a library (a file named by mistake): left as it is
                raise ConfigError(f"{self.path}: not a take library ({err}) and no journal of one beside it; "
                                  "pass --library with the library's file (a new name starts a new one)") from err
            self.con = self._rebuild(str(err))
        else:
            if new and self.journal.exists() and self.journal.stat().st_size:
                self.con.close()  # emptied or deleted while its journal names takes
                self.con = self._rebuild("it was empty", keep=False)
        self.con.row_factory = sqlite3.Row

    def close(self) -> None:
        self.con.close()

    def __enter__(self) -> Library:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ---- journal and rebuild -------------------------------------------------------------

    def _journaled(self) -> bool:
        """Whether the journal beside the file names anything: a library's rebuild has takes to read."""
        try:
            return self.journal.stat().st_size > 0
        except OSError:
            return False

    def _log(self, **rec: Any) -> None:
        line = (json.dumps(rec, ensure_ascii=False, separators=(",", ":")) + "\n").encode()
        try:
            fd = os.open(self.journal, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
            try:
                os.write(fd, line)
            finally:
                os.close(fd)
        except OSError as err:
            self.warn(f"{self.journal}: cannot append to the library's journal ({err.strerror}); "
                      "the library holds the change, a rebuild would not")

    def _rebuild(self, reason: str, keep: bool = True) -> sqlite3.Connection:
        """Move the damaged file aside and build a new one from the journal and the takes. A lock
        file makes two processes that find the damage at once rebuild it only once."""
        reason = " ".join(reason.replace("*** in database main ***", "").split())[:100]
        try:
            lock = open(self.path.with_name(self.path.name + ".lock"), "a")
        except OSError as err:
            raise ConfigError(f"{self.path}: the take library is damaged ({reason}) and its folder is not "
                              f"writable ({err.strerror}); pass --library with another file") from err
        try:
            fcntl.flock(lock, fcntl.LOCK_EX)
            try:
                con, new = schema.connect(self.path)  # another process rebuilt it meanwhile?
                if not new and con.execute("SELECT count(*) FROM takes").fetchone()[0]:
                    return con
                con.close()
            except schema.LibraryDamaged:
                pass
            stamp = _dt.datetime.now().strftime("%Y%m%d-%H%M%S")
            aside = self.path.with_name(f"{self.path.name}.damaged-{stamp}")
            try:
                for suffix in ("", "-wal", "-shm"):
                    src = Path(str(self.path) + suffix)
                    if src.exists():
                        if keep:
                            os.replace(src, Path(str(aside) + suffix))
                        else:
                            src.unlink()
            except OSError as err:
                raise ConfigError(f"{self.path}: the take library is damaged ({reason}) and cannot be moved "
                                  f"aside ({err.strerror}); move it away and run the command again") from err
            con, _ = schema.connect(self.path)
            con.row_factory = sqlite3.Row
            self.con = con
            found, lost = self._replay_journal()
            kept = f"kept as {aside.name} and " if keep else ""
            self.warn(f"{self.path}: the take library was damaged ({reason}); {kept}rebuilt "
                      f"from the takes: {found} registered" + (f", {lost} no longer found" if lost else "")
                      + "; `puppet takes check` remakes thumbnails and expressions")
            return con
        finally:
            lock.close()

    def _read_journal(self) -> list[dict[str, Any]]:
        try:
            text = self.journal.read_text(encoding="utf-8", errors="replace")
        except OSError:
            return []
        out = []
        for line in text.splitlines():
            try:
                rec = json.loads(line)
            except (ValueError, RecursionError):
                continue  # a line cut by a crash, or damage (nested thousands deep): the rest still counts
            if isinstance(rec, dict) and isinstance(rec.get("op"), str):
                out.append(rec)
        return out

    def _replay_journal(self) -> tuple[int, int]:
        recs = self._read_journal()
        # a take is known by its content hash, or by "rec:PATH" while its recording is not completed;
        # the takes get their ids back in the order they were first mentioned (registered, or begun)
        order: dict[str, None] = {}
        where: dict[str, str] = {}  # key -> latest known path
        performer: dict[str, str] = {}
        begun_tags: dict[str, list[str]] = {}  # key -> the tags given when its recording began
        pending: dict[str, str] = {}  # path -> the key of the recording begun there, until it completes
        for r in recs:
            p, h = r.get("path"), r.get("hash")
            if not isinstance(p, str):
                continue
            if r["op"] == "recording":
                k = pending[p] = "rec:" + p
                order.setdefault(k)
                where[k] = p
                tags = r.get("tags")
                tags = tags if isinstance(tags, list) else []  # a damaged line: no tags rather than none of it
                begun_tags.setdefault(k, []).extend(t for t in tags if isinstance(t, str))
                if isinstance(r.get("performer"), str) and r["performer"]:
                    performer[k] = r["performer"]
            elif r["op"] in ("take", "moved") and isinstance(h, str):
                k = pending.pop(p, None) if r["op"] == "take" else None
                if k is not None:  # the recording begun at p completed as h: h takes its place
                    if h in order:
                        del order[k]
                    else:
                        order = {(h if x == k else x): None for x in order}
                    where.pop(k, None)
                    begun_tags.setdefault(h, []).extend(begun_tags.pop(k, []))
                    if k in performer:
                        performer.setdefault(h, performer.pop(k))
                order.setdefault(h)
                where[h] = p
                if r["op"] == "take" and isinstance(r.get("performer"), str) and r["performer"]:
                    performer[h] = r["performer"]  # (a take's performer is never cleared)
        found = lost = 0
        done: set[str] = set()
        for k in order:
            p = where[k]
            if p in done:
                continue
            done.add(p)
            try:
                info = read_take_info(p)
            except (ConfigError, PuppetError, OSError, ValueError):
                lost += 1
                continue
            if where.get(info.hash, p) != p:
                continue  # the take moved on; registered at its newer place
            info.performer = performer.get(info.hash) or performer.get(k) or info.performer
            take_id = self._register(info, journal=False)
            if k.startswith("rec:") and recording_alive(p, None):  # still being recorded: its show completes it
                self.set_state(take_id, "recording")
            for t in begun_tags.get(k, []) + (begun_tags.get(info.hash, []) if info.hash != k else []):
                try:
                    self._tag(take_id, t, False, journal=False)
                except PuppetError:
                    continue
            found += 1
        for r in recs:
            h = r.get("hash")
            if not isinstance(h, str):
                continue
            for row in self.con.execute("SELECT id FROM takes WHERE hash = ?", (h,)).fetchall():
                try:
                    if r["op"] == "tag" and isinstance(r.get("tag"), str):
                        self._tag(row[0], r["tag"], bool(r.get("remove")), journal=False)
                    elif r["op"] == "note" and isinstance(r.get("text"), str):
                        self._note(row[0], r["text"], journal=False)
                except PuppetError:
                    continue
        return found, lost

    # ---- writing ---------------------------------------------------------------------------

    def register(self, path: str | Path, performer: str | None = None, tags: Iterable[str] = (),
                 unchanged: list[int] | None = None) -> int:
        """Add (or refresh) the take at `path`; returns its id. A take whose content is already
        registered at a place where it is missing is taken as moved there. With `unchanged` (a
        list; not with `performer`), a take found registered there with the same content, complete,
        is left as it is and its id appended (decided inside the write: another process may have
        registered it since the caller looked)."""
        info = read_take_info(path)
        for w in info.warnings:
            self.warn(w)
        if performer:
            info.performer = str(performer)[:200]
        take_id = self._register(info, unchanged=unchanged)
        for t in tags:
            self.tag(take_id, t)
        return take_id

    def _register(self, info: TakeInfo, journal: bool = True, unchanged: list[int] | None = None) -> int:
        """The take's entry made or completed from what its file holds: `complete` when the take
        ended cleanly, `crashed` when its show died (the file read up to its last whole tick)."""
        with schema.write(self.con) as con:
            if unchanged is not None and info.ended:
                same = con.execute("SELECT id FROM takes WHERE path = ? AND hash = ? AND missing = 0 AND "
                                   "state = 'complete'", (info.path, info.hash)).fetchone()
                if same is not None:
                    unchanged.append(int(same[0]))
                    return int(same[0])
            row = con.execute("SELECT id, hash, performer FROM takes WHERE path = ?", (info.path,)).fetchone()
            if row is None:
                row = con.execute("SELECT id, hash, performer FROM takes WHERE hash = ? AND missing = 1",
                                  (info.hash,)).fetchone()
            fields = dict(path=info.path, hash=info.hash, size=info.size, recorded=info.recorded,
                          duration=info.duration, ticks=info.ticks, tick_rate=info.tick_rate, face=info.face,
                          identity=info.identity, resolution=info.resolution, program=info.program,
                          devices=info.devices_json(), markers=info.markers_json(), missing=0,
                          state="complete" if info.ended else "crashed", recorder=None)
            if row is None:
                fields.update(performer=info.performer, registered=_now())
                cols = ", ".join(fields)
                con.execute(f"INSERT INTO takes ({cols}) VALUES ({', '.join('?' * len(fields))})",
                            tuple(fields.values()))
                take_id = int(con.execute("SELECT last_insert_rowid()").fetchone()[0])
            else:
                take_id = int(row[0])
                if info.performer:
                    fields["performer"] = info.performer
                if row[1] != info.hash:
                    fields["analysed"] = 0
                    con.execute("DELETE FROM spans WHERE take_id = ?", (take_id,))
                con.execute(f"UPDATE takes SET {', '.join(f'{k} = ?' for k in fields)} WHERE id = ?",
                            (*fields.values(), take_id))
            self._reindex(con, take_id)
        if journal:
            self._log(op="take", path=info.path, hash=info.hash, performer=info.performer)
        return take_id

    def begin(self, path: str | Path, header: dict[str, Any], performer: str | None = None,
              tags: Iterable[str] = (), journal: bool = True) -> int:
        """Register a take whose recording starts now, from its header (date, face and identity,
        devices, performer) and the command line's tags; its state is `recording` until `register`
        completes it when the show ends, or `puppet takes check` after the show died. A take at
        `path` already registered (a recording resumed after a crash) keeps its id, tags and notes."""
        p = str(Path(path).resolve())
        head = header_fields(header)
        if performer:
            head["performer"] = str(performer)[:200]
        tags = [clean_tag(t) for t in tags]
        fields = dict(path=p, hash="", size=0, duration=0.0, ticks=0, markers="[]", missing=0, analysed=0,
                      state="recording", recorder=recorder_id(), **head)
        fields["devices"] = json.dumps(head["devices"])
        with schema.write(self.con) as con:
            row = con.execute("SELECT id FROM takes WHERE path = ?", (p,)).fetchone()
            if row is None:
                fields["registered"] = _now()
                con.execute(f"INSERT INTO takes ({', '.join(fields)}) VALUES ({', '.join('?' * len(fields))})",
                            tuple(fields.values()))
                take_id = int(con.execute("SELECT last_insert_rowid()").fetchone()[0])
            else:
                take_id = int(row[0])
                if not fields["performer"]:
                    del fields["performer"]
                con.execute("DELETE FROM spans WHERE take_id = ?", (take_id,))
                con.execute(f"UPDATE takes SET {', '.join(f'{k} = ?' for k in fields)} WHERE id = ?",
                            (*fields.values(), take_id))
            con.executemany("INSERT OR IGNORE INTO tags (take_id, tag) VALUES (?, ?)", [(take_id, t) for t in tags])
            self._reindex(con, take_id)
        if journal:
            self._log(op="recording", path=p, performer=head["performer"], tags=tags)
        return take_id

    def _reindex(self, con: sqlite3.Connection, take_id: int) -> None:
        t = con.execute("SELECT * FROM takes WHERE id = ?", (take_id,)).fetchone()
        tags = " ".join(r[0] for r in con.execute("SELECT tag FROM tags WHERE take_id = ?", (take_id,)))
        exprs = " ".join(sorted({r[0] for r in con.execute("SELECT expression FROM spans WHERE take_id = ?",
                                                             (take_id,))}))
        p = Path(t["path"])
        markers = " ".join(m[1] for m in json.loads(t["markers"] or "[]"))
        devices = " ".join(json.loads(t["devices"] or "[]"))
        con.execute("DELETE FROM takes_text WHERE rowid = ?", (take_id,))
        con.execute("INSERT INTO takes_text (rowid, name, performer, notes, tags, markers, expressions, devices, face) "
                    "VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)",
                    (take_id, f"{p.parent.name} {p.stem}", t["performer"], t["notes"], tags, markers, exprs,
                     devices, t["face"] or ""))

    def _take(self, take_id: int) -> sqlite3.Row:
        # an id past SQLite's 64-bit integers (typed on a command line, a page's URL) is no take
        # either: the query raised OverflowError (a traceback; the page's a 500)
        row = None if not -(1 << 63) <= take_id < (1 << 63) else \
            self.con.execute("SELECT * FROM takes WHERE id = ?", (take_id,)).fetchone()
        if row is None:
            raise PuppetError(f"no take {take_id} in the library {self.path} (see `puppet takes list`)")
        return row

    def tag(self, take_id: int, tag: str, remove: bool = False) -> None:
        self._tag(take_id, tag, remove)

    def _tag(self, take_id: int, tag: str, remove: bool, journal: bool = True) -> None:
        t = clean_tag(tag)
        h = self._take(take_id)["hash"]
        with schema.write(self.con) as con:
            if remove:
                con.execute("DELETE FROM tags WHERE take_id = ? AND tag = ?", (take_id, t))
            else:
                con.execute("INSERT OR IGNORE INTO tags (take_id, tag) VALUES (?, ?)", (take_id, t))
            self._reindex(con, take_id)
        if journal:
            self._log(op="tag", hash=h, tag=t, remove=remove)

    def note(self, take_id: int, text: str) -> None:
        self._note(take_id, text)

    def _note(self, take_id: int, text: str, journal: bool = True) -> None:
        text = str(text).strip()
        if len(text) > MAX_NOTE:
            raise PuppetError(f"a note is at most {MAX_NOTE} characters, got {len(text)}")
        h = self._take(take_id)["hash"]
        with schema.write(self.con) as con:
            con.execute("UPDATE takes SET notes = ? WHERE id = ?", (text, take_id))
            self._reindex(con, take_id)
        if journal:
            self._log(op="note", hash=h, text=text)

    def set_analysis(self, take_id: int, digest: str, thumbnail: bytes | None,
                     spans: list[tuple[float, float, str, float]]) -> None:
        """Store a take's thumbnail and expression spans, made from the content `digest` (ignored
        if the take changed meanwhile)."""
        with schema.write(self.con) as con:
            row = con.execute("SELECT hash FROM takes WHERE id = ?", (take_id,)).fetchone()
            if row is None or row[0] != digest:
                return
            con.execute("DELETE FROM spans WHERE take_id = ?", (take_id,))
            con.executemany("INSERT INTO spans (take_id, start, end, expression, score) VALUES (?, ?, ?, ?, ?)",
                            [(take_id, *s) for s in spans])
            con.execute("UPDATE takes SET thumbnail = ?, analysed = 1 WHERE id = ?", (thumbnail, take_id))
            self._reindex(con, take_id)

    def set_spans(self, digest: str, spans: list[tuple[float, float, str, float]]) -> int:
        """Store the expression spans found in the take whose content hash is `digest` (every
        registered copy of it; its thumbnail is left as it is); returns how many takes got them."""
        with schema.write(self.con) as con:
            ids = [r[0] for r in con.execute("SELECT id FROM takes WHERE hash = ?", (digest,))]
            for take_id in ids:
                con.execute("DELETE FROM spans WHERE take_id = ?", (take_id,))
                con.executemany("INSERT INTO spans (take_id, start, end, expression, score) VALUES (?, ?, ?, ?, ?)",
                                [(take_id, *s) for s in spans])
                self._reindex(con, take_id)
        return len(ids)

    def follow(self, old: str | Path, new: str | Path) -> None:
        """The take registered at `old` was moved to `new` (its content there unchanged): its entry,
        tags and notes go with it, so whatever is recorded at `old` next is a take of its own. A
        take whose show died before completing its entry is completed from the file at `new`."""
        old_path, new_path = str(Path(old).resolve()), str(Path(new).resolve())
        row = self.con.execute("SELECT id, hash, state FROM takes WHERE path = ?", (old_path,)).fetchone()
        if row is None:
            return
        if row[2] == "recording" and not row[1]:  # its show died before completing it: completed there
            with schema.write(self.con) as con:
                con.execute("UPDATE takes SET path = ? WHERE id = ?", (new_path, int(row[0])))
            try:
                self.register(new_path)
            except (ConfigError, PuppetError):
                self.set_state(int(row[0]), "damaged")
        elif file_hash(new_path)[0] == row[1]:
            self.set_place(int(row[0]), new_path, False)

    def set_state(self, take_id: int, state: str) -> None:
        """Mark a take's entry (`damaged`: its file no longer holds this take; its details, tags
        and notes are kept, so the take is found again by its hash)."""
        with schema.write(self.con) as con:
            con.execute("UPDATE takes SET state = ? WHERE id = ?", (state, take_id))

    def set_place(self, take_id: int, path: str | None, missing: bool) -> None:
        with schema.write(self.con) as con:
            if path is not None:
                con.execute("UPDATE takes SET path = ?, missing = 0 WHERE id = ?", (path, take_id))
                self._reindex(con, take_id)
            else:
                con.execute("UPDATE takes SET missing = ? WHERE id = ?", (int(missing), take_id))
        if path is not None:
            self._log(op="moved", hash=self._take(take_id)["hash"], path=path)

    # ---- reading ---------------------------------------------------------------------------

    def get(self, take_id: int) -> dict[str, Any]:
        row = self._take(take_id)
        d = dict(row)
        d["devices"] = json.loads(d["devices"] or "[]")
        d["markers"] = json.loads(d["markers"] or "[]")
        if d["state"] == "recording" and not recording_alive(d["path"], d["recorder"]):
            d["state"] = "died"  # its show was killed: `puppet takes check` completes the entry
        d["tags"] = [r[0] for r in self.con.execute("SELECT tag FROM tags WHERE take_id = ? ORDER BY tag", (take_id,))]
        d["expressions"] = [dict(start=r[0], end=r[1], expression=r[2], score=r[3]) for r in self.con.execute(
            "SELECT start, end, expression, score FROM spans WHERE take_id = ? ORDER BY start", (take_id,))]
        return d

    def all_ids(self) -> list[int]:
        return [r[0] for r in self.con.execute("SELECT id FROM takes ORDER BY id")]

    def search(self, query: str = "") -> list[dict[str, Any]]:
        """Takes matching `query`: words (full text over name, performer, notes, tags, markers,
        expressions, devices, face; prefixes match) and filters `performer:NAME`, `tag:T`,
        `expression:E`, `date:YYYY-MM-DD` (or a prefix: `date:2026-12`), `after:DATE`,
        `before:DATE`, `missing:yes|no`, `face:NAME`, `state:complete|recording|crashed|damaged`.
        All must hold."""
        where, params = [], []
        words = []
        try:
            tokens = shlex.split(query)
        except ValueError as err:
            raise PuppetError(f"cannot read the query {query!r:.80}: {err}") from err
        for tok in tokens:
            key, sep, val = tok.partition(":")
            key = key.lower()
            if not sep or key not in ("performer", "tag", "expression", "expr", "date", "after", "before",
                                      "missing", "face", "id", "state"):
                words.append(tok)
                continue
            if key == "performer":
                where.append("lower(t.performer) = lower(?)")
                params.append(val)
            elif key == "tag":
                where.append("EXISTS (SELECT 1 FROM tags g WHERE g.take_id = t.id AND g.tag = ?)")
                params.append(clean_tag(val))
            elif key in ("expression", "expr"):
                where.append("EXISTS (SELECT 1 FROM spans s WHERE s.take_id = t.id AND s.expression = lower(?))")
                params.append(val)
            elif key in ("date", "after", "before") and not _date_prefix(val):
                raise PuppetError(f"query {tok!r:.80}: a date is YYYY-MM-DD or the start of one "
                                  f"({key}:2026-12-03, {key}:2026-12)")
            elif key == "date":
                where.append("substr(t.recorded, 1, length(?)) = ?")
                params += [val, val]
            elif key == "after":
                where.append("t.recorded >= ?")
                params.append(val)
            elif key == "before":
                where.append("t.recorded < ?")
                params.append(val)
            elif key == "missing" and val.lower() not in ("yes", "no", "1", "0", "true", "false"):
                # `missing:maybe` was taken as no and `state:crash` matched nothing, without a word
                raise PuppetError(f"query {tok!r:.80}: missing: takes yes or no")
            elif key == "state" and val.lower() not in QUERY_STATES:
                raise PuppetError(f"query {tok!r:.80}: state: takes {', '.join(QUERY_STATES)}")
            elif key == "missing":
                where.append("t.missing = ?")
                params.append(1 if val.lower() in ("yes", "1", "true") else 0)
            elif key == "state":
                where.append("t.state = lower(?)")
                params.append("recording" if val.lower() == "died" else val.lower())
            elif key == "face":
                where.append("t.face = ?")
                params.append(val)
            elif key == "id":
                where.append("t.id = ?")
                # an id past SQLite's 64-bit integers (OverflowError) or of other scripts' digits
                # (`id:²`, a ValueError for int) was a traceback: no take has it
                params.append(int(val) if val.isascii() and val.isdigit() and len(val) < 19 else -1)
        if words:
            fts = " AND ".join('"' + w.replace('"', '""') + '"*' for w in words)
            where.append("t.id IN (SELECT rowid FROM takes_text WHERE takes_text MATCH ?)")
            params.append(fts)
        sql = "SELECT t.id FROM takes t" + (" WHERE " + " AND ".join(where) if where else "") + \
              " ORDER BY t.recorded, t.id"
        try:
            ids = [r[0] for r in self.con.execute(sql, params)]
        except sqlite3.OperationalError as err:
            raise PuppetError(f"cannot search for {query!r:.80}: {err}") from err
        return [self.get(i) for i in ids]


def recorder_id() -> str:
    """Who records a take: "HOST PID" of this process."""
    return f"{socket.gethostname()} {os.getpid()}"


def recording_alive(path: str | Path, recorder: str | None) -> bool:
    """Whether the show that began recording the take at `path` still records it: it holds the
    recording's lock (which the kernel drops when the process dies, SIGKILL included), or, where
    the file system has no locks, its process on this host still runs (another host's show is
    taken as alive)."""
    from puppet.session import _being_recorded

    if _being_recorded(Path(path)):
        return True
    host, _, pid = (recorder or "").rpartition(" ")
    if not (pid.isascii() and pid.isdigit() and len(pid) < 10):  # int() or os.kill would raise
        return False
    if host != socket.gethostname():
        return True
    try:
        os.kill(int(pid), 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return _locks_unsupported(Path(path))


def _locks_unsupported(path: Path) -> bool:
    """Whether flock does nothing on the file system of `path` (then a live process is the only sign)."""
    from puppet.session import lock_probe

    return lock_probe(path) == "unsupported"


def _date_prefix(text: str) -> bool:
    """`2026`, `2026-12`, `2026-12-03` (a real day), or that followed by a time (T10, T10:15, ...)."""
    import re
    from datetime import date

    m = re.fullmatch(r"(\d{4})(?:-(\d{2})(?:-(\d{2})(?:[T ]\d{2}(?::\d{2}(?::\d{2}(?:\.\d+)?)?)?)?)?)?", text)
    if m is None:
        return False
    y, mo, d = int(m[1]), int(m[2] or 1), int(m[3] or 1)
    try:
        date(y, mo, d)
    except ValueError:
        return False
    return True


def find_by_hash(digest: str, size: int, roots: Iterable[Path], limit: int = 200_000) -> str | None:
    """A `.jsonl` file under `roots` whose size and then SHA-256 equal the take's."""
    seen = 0
    for root in roots:
        try:
            walker = os.walk(root)
            for folder, dirs, files in walker:
                dirs[:] = [d for d in dirs if not d.startswith(".")]
                for name in files:
                    seen += 1
                    if seen > limit:
                        return None
                    if not name.endswith(".jsonl"):
                        continue
                    p = Path(folder) / name
                    try:
                        if p.stat().st_size != size:
                            continue
                        if file_hash(p)[0] == digest:
                            return str(p.resolve())
                    except (OSError, ConfigError):
                        continue
        except OSError:
            continue
    return None
