"""Reading and writing user files safely, shared by every format the program has.

Reading: a file is read with a size bound, decoded as UTF-8 with a line number on failure, parsed
as JSON or TOML with a nesting bound, and its fields checked with small schema helpers (type,
range, finiteness, length). Every failure is a `BadFile` whose message is one short line naming
the file (and line), quoting at most a short prefix of the offending value.

Writing: `atomic_write` / `atomic_path` / `atomic_dir` write to a temporary file (or folder) beside
the target and move it into place only when it is complete, so a failed or killed write leaves the
old file byte for byte. Knows nothing of faces, devices or OpenGL: any package may use it."""

from __future__ import annotations

import errno
import json
import math
import os
import shutil
import select
import stat
import sys
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO, Any

#: Bounds a file's content cannot exceed (a typo or a damaged disk must not eat the memory).
MAX_BYTES = 256 * 1024 * 1024
MAX_DEPTH = 32
QUOTE_CHARS = 40


class BadFile(ValueError):
    """A file the user gave cannot be used; the message is one line naming it (and its line)."""


def quote(value: Any, limit: int = QUOTE_CHARS) -> str:
    """`repr(value)` cut to a short prefix (an error line never carries a whole bad value)."""
    if isinstance(value, int) and not isinstance(value, bool) and value.bit_length() > 128:
        return f"an integer of about {int(value.bit_length() * 0.30103) + 1} digits"
    try:
        text = repr(value)
    except Exception:  # a repr that fails (recursive or huge object)
        text = f"<{type(value).__name__}>"
    text = text.replace("\n", "\\n").replace("\r", "\\r")
    if len(text) <= limit:
        return text
    return f"{text[:limit]}... ({len(text)} chars)"


def few(names: list[str] | tuple[str, ...], n: int = 8) -> str:
    """The first `n` names (each cut short) and how many more: a listing in an error stays short."""
    if not names:
        return "none"
    more = f" and {len(names) - n} more" if len(names) > n else ""
    return ", ".join(x if len(x) <= QUOTE_CHARS else quote(x) for x in names[:n]) + more


# ---------------------------------------------------------------------------------------- reading

def file_kind(path: str | Path) -> str:
    """"file", "folder", "missing" or "other" (a pipe, a socket, a device): what a name given
    as a file to read is, so the message can say what is wrong instead of "no such file"."""
    try:
        st = os.stat(path)
    except (OSError, ValueError):
        return "missing"
    if stat.S_ISREG(st.st_mode):
        return "file"
    return "folder" if stat.S_ISDIR(st.st_mode) else "other"


def not_a_file(path: str | Path, what: str) -> str | None:
    """None for a regular file, else the one line for a name that is not one: `what` is e.g.
    "capture file"."""
    kind = file_kind(path)
    if kind == "file":
        return None
    if kind == "missing":
        return f"{path}: no such {what}"
    if kind == "folder":
        return f"{path}: is a folder, not a {what}"
    return f"{path}: not a regular file (a pipe or a device); save it as a file and name that"


#: Seconds a pipe may stay silent before the reader is told what is being waited for.
PIPE_NOTICE_S = 1.0


def _open_to_read(p: Path, what: str) -> Any:
    """`open(p, "rb")`, except for a named pipe (`mkfifo take.jsonl`, or the shell's `<(...)`):
    opening one blocked until a writer came, silently, forever when none does. It is opened
    without blocking and watched; after PIPE_NOTICE_S of nothing one line says what is waited for
    (Ctrl+C stops), then the wait goes on, and what comes is read from that same opening."""
    try:
        fifo = stat.S_ISFIFO(os.stat(p).st_mode)
    except (OSError, ValueError):
        fifo = False
    if not fifo:
        return open(p, "rb")
    fd = os.open(p, os.O_RDONLY | os.O_NONBLOCK)
    try:
        poller = select.poll()
        poller.register(fd, select.POLLIN | select.POLLHUP)
        if not poller.poll(PIPE_NOTICE_S * 1000):
            print(f"puppet: {p}: the {what} is a pipe and nothing has been written to it yet; waiting "
                  "(Ctrl+C stops)", file=sys.stderr, flush=True)
            while not poller.poll(1000):
                pass
        os.set_blocking(fd, True)  # a writer is there: reads wait for its bytes, 0 when it closes
        return os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise


def _unreadable(source: object, what: str, err: OSError) -> BadFile:
    """The one line for a file that cannot be opened or read."""
    if isinstance(err, FileNotFoundError):
        return BadFile(f"{source}: cannot read {what} (no such file)")
    if isinstance(err, IsADirectoryError):
        return BadFile(f"{source}: cannot read {what} (it is a folder)")
    return BadFile(f"{source}: cannot read {what} ({err.strerror or err})")


def _too_large(source: object, what: str, limit: int) -> BadFile:
    """The one line for a file over its bound."""
    return BadFile(f"{source}: the {what} is larger than {limit // (1024 * 1024)} MB; is it the right file?")


@contextmanager
def open_to_read(path: str | Path, what: str) -> Iterator[IO[bytes]]:
    """The file opened for reading in binary (a pipe watched as `read_bytes` does); a name that
    cannot be opened is a `BadFile` naming it. For readers that stream a file line by line, each
    line bounded (`bounded_lines`), instead of holding it whole."""
    p = Path(path)
    try:
        fh = _open_to_read(p, what)
    except OSError as err:
        raise _unreadable(p, what, err) from err
    with fh:
        yield fh


def bounded_lines(fh: IO[bytes], source: str, what: str, line_limit: int,
                  limit: int = MAX_BYTES) -> Iterator[bytes]:
    """The lines of an open file (each with its newline, the last one perhaps without), reading
    at most `limit` bytes in all and `line_limit + 1` for any one line: a line longer than
    `line_limit` is yielded cut there (it has no newline, so a parser sees it as damaged) and ends
    the reading, so a file of one endless line (/dev/zero, a binary file) costs one bound's read;
    a file longer than `limit` is a `BadFile` raised once that much has been read."""
    total = 0
    while True:
        try:
            line = fh.readline(line_limit + 1)
        except OSError as err:
            raise _unreadable(source, what, err) from err
        if not line:
            return
        total += len(line)
        if total > limit:
            raise _too_large(source, what, limit)
        yield line
        if len(line) > line_limit and not line.endswith(b"\n"):
            return


def read_bytes(path: str | Path, what: str, limit: int = MAX_BYTES) -> bytes:
    """The file's bytes; a file larger than `limit` is refused after reading `limit + 1` bytes at
    most (never more, whatever the file claims or holds)."""
    p = Path(path)
    try:
        with _open_to_read(p, what) as fh:
            st = os.fstat(fh.fileno())
            if stat.S_ISREG(st.st_mode) and st.st_size > limit:  # said at once, nothing read
                raise _too_large(p, what, limit)
            data = fh.read(limit + 1)
    except OSError as err:
        raise _unreadable(p, what, err) from err
    if len(data) > limit:
        raise _too_large(p, what, limit)
    return data


def decode_text(data: bytes, source: str, what: str) -> str:
    """UTF-8 text (a leading byte-order mark is dropped); a wrong encoding names the line."""
    if data.startswith(b"\xef\xbb\xbf"):
        data = data[3:]
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as err:
        line = data.count(b"\n", 0, err.start) + 1
        hint = " (it looks like UTF-16: save it as UTF-8)" if data[:2] in (b"\xff\xfe", b"\xfe\xff") else ""
        raise BadFile(f"{source}:{line}: the {what} is not UTF-8 text{hint}") from err
    if "\x00" in text:
        line = text.count("\n", 0, text.index("\x00")) + 1
        raise BadFile(f"{source}:{line}: the {what} holds a NUL byte (a damaged or binary file)")
    return text


def read_text(path: str | Path, what: str, limit: int = MAX_BYTES) -> str:
    """`read_bytes` then `decode_text`."""
    return decode_text(read_bytes(path, what, limit), str(path), what)


def _no_constant(name: str) -> float:
    raise ValueError(f"non-finite number {name}")


def _finite_float(text: str) -> float:
    x = float(text)
    if not math.isfinite(x):
        raise ValueError(f"number {text[:20]} is too large for a float")
    return x


def depth(value: Any, limit: int = MAX_DEPTH) -> int:
    """Nesting depth of lists/dicts in `value`, counted without recursion, stopping past `limit`."""
    deepest = 0
    stack: list[tuple[Any, int]] = [(value, 1)]
    while stack:
        v, d = stack.pop()
        if isinstance(v, dict):
            items: Any = v.values()
        elif isinstance(v, list):
            items = v
        else:
            continue
        deepest = max(deepest, d)
        if deepest > limit:
            return deepest
        stack.extend((x, d + 1) for x in items)
    return deepest


def load_json(text: str, source: str, what: str, max_depth: int = MAX_DEPTH) -> Any:
    """JSON with no NaN/Infinity, no float overflow, bounded nesting; errors name file:line."""
    try:
        value = json.loads(text, parse_constant=_no_constant, parse_float=_finite_float)
    except json.JSONDecodeError as err:
        raise BadFile(f"{source}:{err.lineno}: not valid JSON ({err.msg})") from err
    except RecursionError as err:
        raise BadFile(f"{source}: the {what} is nested too deep (more than {max_depth} levels)") from err
    except ValueError as err:  # non-finite number, integer with thousands of digits
        raise BadFile(f"{source}: the {what} holds an unusable number ({str(err)[:60]})") from err
    if depth(value, max_depth) > max_depth:
        raise BadFile(f"{source}: the {what} is nested too deep (more than {max_depth} levels)")
    return value


def toml_end(text: str) -> str:
    """LINE:COLUMN just past the last character that is not a line break: where tomllib's "at end
    of document" error is (a value cut short on the file's last line)."""
    body = text.rstrip("\r\n")
    line = body.count("\n") + 1
    return f"{line}:{len(body) - (body.rfind(chr(10)) + 1) + 1}"


def load_toml(text: str, source: str, what: str, max_depth: int = MAX_DEPTH) -> dict[str, Any]:
    """TOML with bounded nesting; a syntax error names file:line:col."""
    import re
    import tomllib

    try:
        value = tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        msg = str(err)
        m = re.search(r"\(at line (\d+), column (\d+)\)", msg)
        where = f"{m.group(1)}:{m.group(2)}" if m else "1:1"
        if not m and "(at end of document)" in msg:  # was 1:1 for a file cut short on its last line
            where = toml_end(text)
            msg = msg.replace("(at end of document)", "(at the end of the file)")
        what_ = re.sub(r"\s*\(at line \d+, column \d+\)", "", msg) or "invalid TOML"
        raise BadFile(f"{source}:{where}: TOML syntax error: {what_}") from err
    except RecursionError as err:
        raise BadFile(f"{source}: the {what} is nested too deep (more than {max_depth} levels)") from err
    except ValueError as err:  # an integer with thousands of digits
        raise BadFile(f"{source}: the {what} holds an unusable number ({str(err)[:60]})") from err
    if depth(value, max_depth) > max_depth:
        raise BadFile(f"{source}: the {what} is nested too deep (more than {max_depth} levels)")
    return value


# ------------------------------------------------------------------------------ schema-like checks

def number(v: Any, where: str, lo: float = -1e12, hi: float = 1e12, *, integer: bool = False,
           lo_open: bool = False) -> float:
    """A finite number (an int if `integer`) within lo..hi (lo excluded if `lo_open`)."""
    kind = "an integer" if integer else "a number"
    if isinstance(v, bool) or not isinstance(v, (int, float)) or (integer and not isinstance(v, int)):
        raise BadFile(f"{where}: expected {kind}, got {quote(v)}")
    if isinstance(v, float) and not math.isfinite(v):
        raise BadFile(f"{where}: expected a finite number, got {v!r}")
    if (isinstance(v, int) and v.bit_length() > 1000) or v < lo or v > hi or (lo_open and v == lo):
        rel = ">" if lo_open else ">="
        raise BadFile(f"{where}: expected {kind} {rel} {lo:g} and <= {hi:g}, got {quote(v)}")
    return int(v) if integer else float(v)


def string(v: Any, where: str, max_len: int = 200, *, empty: bool = False) -> str:
    if not isinstance(v, str):
        raise BadFile(f"{where}: expected a string, got {quote(v)}")
    if not v and not empty:
        raise BadFile(f"{where}: expected a non-empty string")
    if len(v) > max_len:
        raise BadFile(f"{where}: expected at most {max_len} characters, got {quote(v)}")
    return v


def sequence(v: Any, where: str, max_len: int = 100_000, min_len: int = 0) -> list[Any]:
    if not isinstance(v, list):
        raise BadFile(f"{where}: expected a list, got {quote(v)}")
    if not min_len <= len(v) <= max_len:
        raise BadFile(f"{where}: expected {min_len} to {max_len} entries, got {len(v)}")
    return v


def table(v: Any, where: str, max_len: int = 100_000) -> dict[str, Any]:
    if not isinstance(v, dict):
        raise BadFile(f"{where}: expected an object/table, got {quote(v)}")
    if len(v) > max_len:
        raise BadFile(f"{where}: expected at most {max_len} entries, got {len(v)}")
    return v


# ---------------------------------------------------------------------------------------- writing

#: errno values of a write that found no room (the disk, the quota, the file size limit).
_DISK_FULL = frozenset(getattr(errno, n) for n in ("ENOSPC", "EDQUOT", "EFBIG") if hasattr(errno, n))
#: errno values of an fsync the file system does not offer (the data is not known to be lost).
_NO_SYNC = frozenset(getattr(errno, n) for n in ("EINVAL", "ENOTSUP", "EOPNOTSUPP", "ENOSYS") if hasattr(errno, n))


def fitting_stem(folder: str | Path, stem: str, extra: int) -> str:
    """`stem` cut (in bytes, as the kernel counts, on a character boundary) so that it and `extra`
    more bytes make a name the file system in `folder` takes: a side or temporary file of a name
    near the 255-byte limit is still made."""
    try:
        name_max = os.pathconf(folder if str(folder) else ".", "PC_NAME_MAX")
    except (OSError, ValueError):
        name_max = 255
    raw = os.fsencode(stem)
    if len(raw) + extra <= name_max:
        return stem
    return raw[:max(name_max - extra, 1)].decode("utf-8", "ignore") or "x"


def _temp_name(target: Path, folder: bool = False) -> Path:
    """A fresh hidden name beside `target` that keeps its suffix (encoders choose by suffix)."""
    fd_dir = target.parent if str(target.parent) else Path(".")
    if folder:
        suffix, stem = ".part", target.name
    else:
        suffix, stem = f".part{target.suffix}", target.stem
    # a name the file system takes for the target must not fail for its temporary one: the stem is
    # cut to leave room for the dots, 8 random characters and the suffix
    stem = fitting_stem(fd_dir, stem, 10 + len(os.fsencode(suffix)))
    if folder:
        return Path(tempfile.mkdtemp(prefix=f".{stem}.", suffix=suffix, dir=fd_dir))
    fd, name = tempfile.mkstemp(prefix=f".{stem}.", suffix=suffix, dir=fd_dir)
    os.close(fd)
    return Path(name)


def _mode_for(target: Path) -> int:
    """The permissions the file gets: the old file's, else what a plain open() would give."""
    try:
        return os.stat(target).st_mode & 0o7777
    except OSError:
        umask = os.umask(0)
        os.umask(umask)
        return 0o666 & ~umask


def _commit(tmp: Path, target: Path) -> None:
    os.chmod(tmp, _mode_for(target))
    try:
        with open(tmp, "rb+") as fh:
            os.fsync(fh.fileno())
    except OSError as err:
        if err.errno not in _NO_SYNC:  # the data did not reach the disk: keep the old file
            raise
    os.replace(tmp, target)
    try:  # the rename itself reaches the disk
        dfd = os.open(target.parent if str(target.parent) else ".", os.O_RDONLY)
        try:
            os.fsync(dfd)
        finally:
            os.close(dfd)
    except OSError:
        pass


@contextmanager
def _disk_full_named(target: Path) -> Iterator[None]:
    """A full disk (or quota) met by the caller's writes is one line naming the user's file."""
    try:
        yield
    except OSError as err:
        if err.errno in _DISK_FULL:
            raise BadFile(f"{target}: cannot write: {err.strerror}") from err
        raise


@contextmanager
def atomic_path(target: str | Path) -> Iterator[Path]:
    """A temporary path beside `target` for a writer that wants a file name (an encoder, numpy);
    renamed onto `target` when the block ends without error, removed otherwise."""
    target = Path(target)
    if target.is_dir():
        raise BadFile(f"{target}: is a folder; name a file to write")
    try:
        tmp = _temp_name(target)
    except OSError as err:
        raise BadFile(f"{target}: cannot write: {err.strerror or err}") from err
    held = _hold(tmp)
    try:
        with _disk_full_named(target):
            yield tmp
        try:
            _commit(tmp, target)
        except OSError as err:
            raise BadFile(f"{target}: cannot write: {err.strerror or err}") from err
    except BaseException as err:
        tmp.unlink(missing_ok=True)
        _name_target(err, tmp, target)
        raise
    finally:
        if held is not None:
            os.close(held)


#: the byte range a writer locks in its temporary file: far past any data, an open-file-description
#: lock (F_OFD_SETLK), so it never meets the whole-file flock a take's recorder takes on its file
#: (`puppet fit` writes its take through a temporary file too) and conflicts within one process
_PART_LOCK = (1 << 62, 1)


def _ofd_lock(fd: int, kind: int) -> bool:
    """An OFD write lock (kind F_WRLCK) or its release (F_UNLCK) on `_PART_LOCK`; False when the
    range is held elsewhere. OSError where there are no such locks."""
    import fcntl
    import struct

    op = getattr(fcntl, "F_OFD_SETLK", None)
    if op is None:
        raise OSError("no open-file-description locks here")
    try:
        fcntl.fcntl(fd, op, struct.pack("hhqqi4x", kind, os.SEEK_SET, *_PART_LOCK, 0))
    except (BlockingIOError, PermissionError):
        return False
    return True


def _hold(tmp: Path) -> int | None:
    """An open descriptor holding a lock on the temporary file while it is written (the kernel
    drops it when the writer dies, SIGKILL included): `part_in_use` tells a live writer's file
    from one a killed writer left. None where there are no locks."""
    try:
        import fcntl

        fd = os.open(tmp, os.O_RDWR)
    except (ImportError, OSError):
        return None
    try:
        if _ofd_lock(fd, fcntl.F_WRLCK):
            return fd
    except OSError:
        pass
    os.close(fd)
    return None


def part_in_use(path: str | Path) -> bool:
    """Whether the hidden temporary file `path` is being written now (its writer, in any
    process, holds it; see `_hold`). A file left by a writer that died is not."""
    try:
        import fcntl

        fd = os.open(path, os.O_RDWR)
    except (ImportError, OSError):
        return False
    try:
        if not _ofd_lock(fd, fcntl.F_WRLCK):
            return True
        _ofd_lock(fd, fcntl.F_UNLCK)
        return False
    except OSError:
        return False
    finally:
        os.close(fd)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        return True
    except OSError:
        return False
    finally:
        os.close(fd)
    return False


@contextmanager
def atomic_write(target: str | Path, mode: str = "w", encoding: str | None = "utf-8",
                 newline: str | None = None) -> Iterator[IO[Any]]:
    """`open(target, mode)` that writes a temporary file beside it and renames it into place
    only when the block ends without error; the old file is untouched otherwise."""
    binary = "b" in mode
    with atomic_path(target) as tmp:
        with open(tmp, mode, encoding=None if binary else encoding,
                  newline=None if binary else newline) as fh:
            yield fh


@contextmanager
def atomic_dir(target: str | Path, stale: str | None = None) -> Iterator[Path]:
    """A temporary folder beside `target`; when the block ends without error each file in it is
    renamed into `target` (created if missing) and the files of `target` matching the glob `stale`
    that this write did not make are removed; on error the folder is removed and `target` is left
    as it was."""
    target = Path(target)
    if target.exists() and not target.is_dir():
        raise BadFile(f"{target}: is a file, not a folder; name a folder for the frames (or a file with a suffix)")
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        tmp = _temp_name(target, folder=True)
    except OSError as err:
        raise BadFile(f"{target}: cannot write: {err.strerror or err}") from err
    try:
        with _disk_full_named(target):
            yield tmp
        try:
            target.mkdir(exist_ok=True)
            made = sorted(tmp.iterdir())
            for f in made:
                os.replace(f, target / f.name)
            if stale is not None:  # an earlier, longer export's frames would follow the new ones
                names = {f.name for f in made}
                for old in target.glob(stale):
                    if old.name not in names and old.is_file():
                        old.unlink()
        except OSError as err:
            raise BadFile(f"{target}: cannot write: {err.strerror or err}") from err
    except BaseException as err:
        _name_target(err, tmp, target)
        raise
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def _name_target(err: BaseException, tmp: Path, target: Path) -> None:
    """A writer's error names the file the user gave, never the hidden temporary one."""
    if len(err.args) == 1 and isinstance(err.args[0], str) and str(tmp) in err.args[0]:
        err.args = (err.args[0].replace(str(tmp), str(target)),)
