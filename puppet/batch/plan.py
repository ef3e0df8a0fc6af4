"""What a batch will do, decided on the client before anything runs: the inputs a SELECTION names,
each output's file names, the key that says whether an output is up to date, and the chunks of a
long video. Pure functions and small files; no Dask here."""

from __future__ import annotations

import hashlib
import json
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from puppet.errors import PuppetError
from safefile import atomic_write

#: bumped when the batch outputs' layout or meaning changes (old manifests then no longer match)
PLAN_VERSION = 2
MANIFESTS = ".puppet-batch"
EXPORT_KINDS = {"mp4": ".mp4", "pc2": ".pc2", "csv": ".csv", "arkit": ".arkit.csv", "curves": ".curves"}
MAX_INPUT_BYTES = 512 * 1024 * 1024


@dataclass
class Input:
    path: Path
    files: dict[str, bytes] = field(default_factory=dict)  # the input and its sidecars, by name
    digest: str = ""
    error: str | None = None  # unreadable here: reported, not sent


@dataclass
class Output:
    """One task's result: the files it writes into the output folder."""

    item: Input
    action: str  # export | fit | recognize
    name: str  # the main file's name (export: its suffix picks the kind)
    key: str  # hash of everything the output is made from
    opts: dict[str, Any]
    chunks: list[tuple[int, int]] = field(default_factory=list)  # filled for split videos


def select(selection: list[str], library: str | None, suffixes: tuple[str, ...]) -> list[Path]:
    """Files and folders (every file with one of `suffixes` under it) as given; the remaining
    words form one take-library query."""
    paths: list[Path] = []
    words: list[str] = []
    for s in selection:
        p = Path(s)
        if p.is_dir():
            paths += sorted(q for q in p.rglob("*") if q.is_file() and q.name.lower().endswith(suffixes)
                            and not any(part.startswith(".") for part in q.relative_to(p).parts)
                            and not _channel_export(q) and not _take_sound(q))
        elif p.is_file():
            paths.append(p)
        else:
            words.append(s)
    if words:
        from puppet.library import complete_died, open_library

        query = " ".join(words)
        with open_library(library) as lib:
            complete_died(lib, lambda s: print(f"puppet: {s}", file=sys.stderr))
            found = lib.search(query)
            where = lib.path
        if not found:
            raise PuppetError(f"no file, folder or take in the library {where} matches {query!r:.100} "
                              "(another library: --library PATH)")
        for t in found:
            if t["missing"]:
                raise PuppetError(f"take {t['id']} ({t['path']}) is missing; `puppet takes check` looks for it")
            if t.get("state") == "recording":  # a show records it now: its end is not written yet
                print(f"puppet: warning: take {t['id']} ({t['path']}) is being recorded by a show; left out "
                      "(run the batch again when it ends)", file=sys.stderr)
                continue
            paths.append(Path(t["path"]))
    seen: set[Path] = set()
    out = []
    for p in paths:
        r = p.resolve()
        if r not in seen:
            seen.add(r)
            out.append(r)
    if not out:
        raise PuppetError("the selection names no input files")
    return out


#: how the channel CSV that `puppet replay --out take.csv` writes begins (puppet.export)
CHANNEL_CSV_HEAD = b"frame,time,tick,"


def _channel_export(path: Path) -> bool:
    """A take's channels exported as CSV beside it: in a folder, not a capture to fit or recognize."""
    if not path.name.lower().endswith(".csv"):
        return False
    try:
        with open(path, "rb") as fh:
            return fh.read(len(CHANNEL_CSV_HEAD)) == CHANNEL_CSV_HEAD
    except OSError:
        return False


def _take_sound(path: Path) -> bool:
    """A take's sound (`take.wav` beside `take.jsonl`, recorded from a microphone): in a folder,
    not a voice to fit (a voice's WAV alone is one; they were all left out without a word)."""
    return path.name.lower().endswith(".wav") and path.with_suffix(".jsonl").is_file()


def load(path: Path) -> Input:
    """Read an input and its sidecar (a PC2 capture's rest OBJ) for sending to a worker."""
    item = Input(path)
    names = [path] + ([path.with_suffix(".obj")] if path.suffix.lower() == ".pc2" else [])
    h = hashlib.sha256()
    try:
        for p in names:
            if p != path and not p.exists():
                continue
            if p.stat().st_size > MAX_INPUT_BYTES:
                raise PuppetError(f"{p}: larger than {MAX_INPUT_BYTES >> 20} MB")
            data = p.read_bytes()
            item.files[p.name] = data
            h.update(p.name.encode() + b"\0" + hashlib.sha256(data).digest())
    except OSError as err:
        item.error = f"{path}: cannot read: {err.strerror}"
    except PuppetError as err:
        item.error = str(err)
    item.digest = h.hexdigest()
    return item


#: what an input's name ends with that its outputs do not carry (longest first: `x.arkit.csv` -> `x`)
INPUT_SUFFIXES = (".arkit.csv", ".jsonl", ".csv", ".c3d", ".pc2")


def output_stem(path: Path) -> str:
    """The input's name without its own suffix: `show.1.jsonl` (the earlier take a new recording
    to `show.jsonl` keeps) -> `show.1`, never `show`, so its outputs do not replace the current
    take's; a capture exported as `phone.arkit.csv` -> `phone`."""
    name = path.name
    for suffix in INPUT_SUFFIXES:
        if name.lower().endswith(suffix) and len(name) > len(suffix):
            return name[: -len(suffix)]
    return path.stem or name


def output_names(items: list[Input], suffix: str) -> list[str]:
    """`STEM + suffix` per input; inputs sharing a stem get their content hash's start added."""
    stems = [output_stem(i.path) for i in items]
    dup = {s for s in stems if stems.count(s) > 1}
    return [f"{s}-{i.digest[:8]}{suffix}" if s in dup else f"{s}{suffix}" for s, i in zip(stems, items)]


def output_key(item: Input, action: str, name: str, opts: dict[str, Any]) -> str:
    from puppet import __version__

    text = json.dumps({"v": PLAN_VERSION, "program": __version__, "action": action, "name": name,
                       "input": item.digest, "opts": opts}, sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()


def chunks(frames: int, chunk_frames: int) -> list[tuple[int, int]]:
    """Frame ranges [a, b) of at most chunk_frames frames, the last one not tiny."""
    if chunk_frames <= 0 or frames <= chunk_frames:
        return [(0, frames)]
    n = -(-frames // chunk_frames)
    bounds = [round(k * frames / n) for k in range(n + 1)]
    return [(bounds[k], bounds[k + 1]) for k in range(n)]


def _manifest(out_dir: Path, name: str) -> Path:
    return out_dir / MANIFESTS / f"{name}.json"


def _stamp(path: Path) -> list[int]:
    st = path.stat()
    return [st.st_size, st.st_mtime_ns]


def up_to_date(out_dir: Path, o: Output) -> bool:
    """The output's files exist as its manifest recorded them (size and modification time, as
    `make` judges a target) for this very key: the key holds the inputs' content hashes."""
    try:
        m = json.loads(_manifest(out_dir, o.name).read_text(encoding="utf-8"))
        if not isinstance(m, dict) or m.get("key") != o.key or not isinstance(m.get("files"), dict):
            return False
        for fname, stamp in m["files"].items():
            if _stamp(out_dir / fname) != stamp:
                return False
        return bool(m["files"])
    except (OSError, ValueError, RecursionError):  # damaged (nested thousands deep): the output is redone
        return False


def write_outputs(out_dir: Path, o: Output, files: dict[str, bytes | str]) -> list[Path]:
    """Each file written beside its place and renamed into it, then the manifest (last: an
    interrupted write is redone by the next run). A file given as a text (not bytes) was already
    put in place by the worker (`reach_token`)."""
    written = []
    stamps = {}
    for fname, data in files.items():
        target = out_dir / Path(fname).name
        if not isinstance(data, str):
            with atomic_write(target, "wb") as fh:
                fh.write(data)
        stamps[target.name] = _stamp(target)
        written.append(target)
    m = {"key": o.key, "input": str(o.item.path), "action": o.action, "files": stamps}
    mp = _manifest(out_dir, o.name)
    mp.parent.mkdir(exist_ok=True)
    with atomic_write(mp) as fh:
        fh.write(json.dumps(m, indent=1))
    return written


def reach_token(out_dir: Path) -> dict[str, str]:
    """A random token in a file under the output folder: a worker that reads the same token at the
    same path sees this very folder (this machine's local cluster, or a farm's shared storage) and
    writes its outputs in place instead of sending their bytes back (a scanned head's 10 s point
    cache is ~190 MB). The file lives while the batch runs, is whole before any task is sent and
    a worker that cannot read it just sends the bytes: it is written without the rename and the
    two disk flushes of a kept file (6 ms before the first task, 0.3 ms without)."""
    import secrets

    token = secrets.token_hex(16)
    folder = out_dir / MANIFESTS
    folder.mkdir(exist_ok=True)
    with open(folder / f"reach-{token[:8]}", "x", encoding="utf-8") as fh:
        fh.write(token)
    return {"dir": str(out_dir.resolve()), "token": token}


def reachable(dest: dict[str, str] | None) -> Path | None:
    """The output folder when this process sees the one `reach_token` marked, else None."""
    if not dest:
        return None
    folder = Path(dest["dir"])
    try:
        if (folder / MANIFESTS / f"reach-{dest['token'][:8]}").read_text(encoding="utf-8") == dest["token"]:
            return folder
    except (OSError, KeyError, UnicodeDecodeError):
        pass
    return None


def drop_token(out_dir: Path, dest: dict[str, str]) -> None:
    try:
        (out_dir / MANIFESTS / f"reach-{dest['token'][:8]}").unlink()
    except OSError:
        pass
