"""The take library's SQLite file: its schema, its migrations and how it is opened.

This module alone knows the tables. The file is opened in WAL mode (readers never wait for the
writer), with a busy timeout, and every write is a `BEGIN IMMEDIATE` transaction (see `write`):
two shows recording at once, or a show and `puppet takes` in another terminal, queue for the write
lock instead of failing with "database is locked". `PRAGMA user_version` holds the schema version;
`MIGRATIONS[n]` takes a file from version n to n + 1 inside one transaction, so an interrupted
migration leaves the old version intact.

A file that is not a database, fails SQLite's quick check, or raises a "malformed" error is
damaged: `LibraryDamaged` is raised and the caller (puppet.library.store) rebuilds the file from
the takes and the journal beside it."""

from __future__ import annotations

import os
import sqlite3
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from puppet.errors import ConfigError

#: seconds a writer waits for another writer's transaction before giving up
BUSY_TIMEOUT = 60.0

MIGRATIONS: list[str] = [
    # 0 -> 1: takes, tags, expression spans, full-text index
    """
    CREATE TABLE takes (
        id          INTEGER PRIMARY KEY,
        path        TEXT NOT NULL,
        hash        TEXT NOT NULL,
        size        INTEGER NOT NULL,
        recorded    TEXT,              -- the recording's start time (ISO 8601, UTC)
        registered  TEXT NOT NULL,
        duration    REAL NOT NULL,
        ticks       INTEGER NOT NULL,
        tick_rate   REAL NOT NULL,
        face        TEXT,              -- rig name ('default' for the built-in face)
        identity    TEXT,              -- rig hash: which face exactly
        resolution  INTEGER,
        program     TEXT,
        devices     TEXT NOT NULL DEFAULT '[]',   -- JSON list of device specs
        markers     TEXT NOT NULL DEFAULT '[]',   -- JSON list of [seconds, label]
        performer   TEXT NOT NULL DEFAULT '',
        notes       TEXT NOT NULL DEFAULT '',
        thumbnail   BLOB,              -- a small PNG
        analysed    INTEGER NOT NULL DEFAULT 0,   -- thumbnail and expressions made for this hash
        missing     INTEGER NOT NULL DEFAULT 0    -- the file was not found by the last check
    );
    CREATE UNIQUE INDEX takes_path ON takes(path);
    CREATE INDEX takes_hash ON takes(hash);
    CREATE INDEX takes_performer ON takes(performer);
    CREATE INDEX takes_recorded ON takes(recorded);
    CREATE TABLE tags (
        take_id INTEGER NOT NULL REFERENCES takes(id) ON DELETE CASCADE,
        tag     TEXT NOT NULL,
        PRIMARY KEY (take_id, tag)
    );
    CREATE INDEX tags_tag ON tags(tag);
    CREATE TABLE spans (
        take_id    INTEGER NOT NULL REFERENCES takes(id) ON DELETE CASCADE,
        start      REAL NOT NULL,
        end        REAL NOT NULL,
        expression TEXT NOT NULL,
        score      REAL NOT NULL
    );
    CREATE INDEX spans_take ON spans(take_id);
    CREATE INDEX spans_expression ON spans(expression);
    CREATE VIRTUAL TABLE takes_text USING fts5(
        name, performer, notes, tags, markers, expressions, devices, face,
        tokenize = 'unicode61 remove_diacritics 2'
    );
    """,
    # 1 -> 2: a take is registered when its recording starts; its state says how far it got
    """
    ALTER TABLE takes ADD COLUMN state TEXT NOT NULL DEFAULT 'complete';
    -- complete: ended cleanly | recording: a show is writing it (or died: `takes check` completes it)
    -- crashed: its show died, completed from what the file holds | damaged: the file is no longer this take
    ALTER TABLE takes ADD COLUMN recorder TEXT;   -- "HOST PID" of the show recording it
    CREATE INDEX takes_state ON takes(state);
    """,
]
SCHEMA_VERSION = len(MIGRATIONS)


class LibraryDamaged(Exception):
    """The library file cannot be trusted; the message says why in a few words."""


class LibraryUnwritable(ConfigError):
    """A write the library's file refused (read-only, full, locked): the whole command's error,
    never one take's."""


def _migrate(con: sqlite3.Connection, path: Path) -> int:
    """Bring the file to SCHEMA_VERSION; returns the version it had (0: a new, empty file)."""
    version = con.execute("PRAGMA user_version").fetchone()[0]
    if version > SCHEMA_VERSION:
        raise ConfigError(f"{path}: the take library was written by a newer puppet (schema {version}, this "
                          f"one knows {SCHEMA_VERSION}); upgrade, or pass --library with another file")
    if version == SCHEMA_VERSION:
        return version
    con.execute("BEGIN IMMEDIATE")
    try:
        version = con.execute("PRAGMA user_version").fetchone()[0]  # another process may have migrated
        for n in range(version, SCHEMA_VERSION):
            for stmt in _statements(MIGRATIONS[n]):
                con.execute(stmt)
        con.execute(f"PRAGMA user_version = {SCHEMA_VERSION}")
        con.execute("COMMIT")
    except BaseException:
        con.execute("ROLLBACK")
        raise
    return version


def _statements(script: str) -> Iterator[str]:
    """The script's statements one by one (executescript would commit our transaction)."""
    buf = ""
    for line in script.splitlines(keepends=True):
        buf += line.split("--", 1)[0] if "--" in line else line
        if sqlite3.complete_statement(buf):
            if buf.strip():
                yield buf.strip()
            buf = ""


def _why(path: Path, err: sqlite3.Error) -> str:
    """SQLite's reason, or the system's where SQLite only says "unable to open database file" (a
    library to be made in a folder that cannot be written: a read-only disk, another user's)."""
    if path.exists():
        return str(err)
    try:
        os.close(os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644))
    except OSError as made:
        return f"cannot create it: {made.strerror} (--library PATH names another place)"
    os.unlink(path)
    return str(err)


def connect(path: Path) -> tuple[sqlite3.Connection, bool]:
    """Open (creating) and check the library at `path`, migrated to the current schema; returns
    the connection and whether the file was new (or empty). Raises LibraryDamaged for a damaged
    file, ConfigError for one that cannot be opened at all."""
    if path.is_file() and path.parent.is_dir() and not os.access(path.parent, os.W_OK):
        return _connect_read_only(path), False
    if path.is_dir():  # was "cannot open the take library: unable to open database file"
        raise ConfigError(f"{path}: is a folder, not a take library; pass --library with the library's file, "
                          f"e.g. {path / 'takes.db'}")
    if path.exists() and not path.is_file():  # a pipe or a device: SQLite said "disk I/O error"
        raise ConfigError(f"{path}: not a regular file (a pipe or a device), not a take library; pass --library "
                          "with the library's file (a new name starts a new one)")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise ConfigError(f"{path}: cannot create the take library's folder: {err.strerror}") from err
    try:
        con = sqlite3.connect(path, timeout=BUSY_TIMEOUT, isolation_level=None, check_same_thread=False)
    except sqlite3.Error as err:
        raise ConfigError(f"{path}: cannot open the take library: {_why(path, err)}") from err
    try:
        if con.execute("PRAGMA user_version").fetchone()[0] == 0:
            other = [r[0] for r in con.execute("SELECT name FROM sqlite_master WHERE type = 'table'")]
            if other:  # another program's database: not ours to change
                con.close()
                raise ConfigError(f"{path}: not a take library (a database with the tables "
                                  f"{', '.join(other[:3])[:80]}); pass --library with the library's file")
        con.execute("PRAGMA foreign_keys = ON")
        mode = con.execute("PRAGMA journal_mode = WAL").fetchone()[0]
        if str(mode).lower() != "wal":
            raise LibraryDamaged(f"cannot switch to WAL mode (got {mode})")
        con.execute("PRAGMA synchronous = NORMAL")
        check = con.execute("PRAGMA quick_check(1)").fetchone()[0]
        if check != "ok":
            raise LibraryDamaged(str(check)[:80])
        was = _migrate(con, path)
        if SCHEMA_VERSION and not con.execute(
                "SELECT count(*) FROM sqlite_master WHERE name IN ('takes','tags','spans','takes_text')").fetchone()[0] == 4:
            raise LibraryDamaged("tables are missing")
    except LibraryDamaged:
        con.close()
        raise
    except sqlite3.OperationalError as err:
        con.close()
        if "locked" in str(err) or "busy" in str(err):
            raise ConfigError(f"{path}: the take library stayed locked by another program for "
                              f"{BUSY_TIMEOUT:g} s") from err
        raise LibraryDamaged(str(err)[:80]) from err
    except sqlite3.DatabaseError as err:
        con.close()
        raise LibraryDamaged(str(err)[:80]) from err
    return con, was == 0


def _connect_read_only(path: Path) -> sqlite3.Connection:
    """The library in a folder this process cannot write (a read-only file system or share): read
    as it is. SQLite cannot open a WAL library there the usual way (it makes its -shm file beside
    it), so the file is opened read-only, and immutable when no -wal file holds later writes. It
    was called damaged; writes to it now say it is read-only (`write_error`)."""
    from urllib.parse import quote

    wal = Path(f"{path}-wal")
    flags = "mode=ro" if wal.exists() and wal.stat().st_size else "mode=ro&immutable=1"
    try:
        con = sqlite3.connect(f"file:{quote(str(path.resolve()))}?{flags}", uri=True, timeout=BUSY_TIMEOUT,
                              isolation_level=None, check_same_thread=False)
        version = con.execute("PRAGMA user_version").fetchone()[0]
        tables = con.execute("SELECT count(*) FROM sqlite_master WHERE name IN "
                             "('takes','tags','spans','takes_text')").fetchone()[0]
        check = con.execute("PRAGMA quick_check(1)").fetchone()[0]
    except sqlite3.Error as err:
        raise ConfigError(f"{path}: cannot read the take library in a folder this program cannot write "
                          f"({err}); copy it somewhere writable and pass --library with the copy") from err
    if version != SCHEMA_VERSION or tables != 4 or check != "ok":
        con.close()
        raise ConfigError(f"{path}: the take library is in a folder this program cannot write and "
                          + ("is damaged" if check != "ok" or tables != 4 else f"has schema {version}, this "
                             f"puppet reads {SCHEMA_VERSION}")
                          + "; copy it somewhere writable and pass --library with the copy")
    return con


@contextmanager
def write(con: sqlite3.Connection) -> Iterator[sqlite3.Connection]:
    """One write transaction that takes the write lock at its start (BEGIN IMMEDIATE): concurrent
    writers wait their turn (busy timeout) rather than fail half way. A write the file refuses (a
    read-only file or file system, a full disk, a lock held past the timeout) is a ConfigError
    naming the library, rolled back: it was a traceback."""
    try:
        con.execute("BEGIN IMMEDIATE")
        try:
            yield con
        except BaseException:
            if con.in_transaction:
                con.execute("ROLLBACK")
            raise
        con.execute("COMMIT")
    except sqlite3.OperationalError as err:
        if con.in_transaction:
            con.execute("ROLLBACK")
        raise write_error(con, err) from err


def write_error(con: sqlite3.Connection, err: sqlite3.OperationalError) -> LibraryUnwritable:
    """The one line for a write the library's file refused."""
    try:
        path = con.execute("PRAGMA database_list").fetchone()[2] or "the take library"
    except sqlite3.Error:
        path = "the take library"
    text = str(err)
    if "readonly" in text or "read-only" in text:
        return LibraryUnwritable(f"{path}: the take library is read-only here ({text}); the change was not "
                                 "written: make it writable, or pass --library with a file you can write")
    if "locked" in text or "busy" in text:
        return LibraryUnwritable(f"{path}: the take library stayed locked by another program for "
                                 f"{BUSY_TIMEOUT:g} s; the change was not written: try again")
    return LibraryUnwritable(f"{path}: cannot write the take library ({text}); the change was not written")
