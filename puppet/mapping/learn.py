"""Learn mode's file side: add or update one binding in a mapping file with tomlkit, so the user's
comments, order and formatting survive. Re-learning a control keeps its filters and settings and
only changes the target (what MIDI-learn users ask for)."""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import tomlkit
from tomlkit.exceptions import TOMLKitError

from puppet.errors import ConfigError
from puppet.mapping.config import parse_mapping
from safefile import BadFile, atomic_write, quote, read_text

NEW_FILE_HEADER = """# facepuppet mapping file (see docs/live.md for every key).
# Written by `puppet learn`; edit freely: comments are kept when learn adds bindings.
"""


def device_key(spec: str) -> str:
    """What a learned binding stores as `device`: the scheme, so the map still works when the box
    comes back on another port (ttyUSB0 -> ttyUSB1)."""
    return spec.split("://", 1)[0] if "://" in spec else spec


def default_settings(kind: str, mode: str | None) -> dict[str, Any]:
    """Starting settings for a freshly learned control of this event kind."""
    if kind == "dial":
        return {"gain": 0.5, "filters": [{"type": "smooth", "rise": 0.04, "fall": 0.08}]}
    if kind == "axis":
        return {"filters": [{"type": "deadzone", "width": 0.02}, {"type": "one_euro", "min_cutoff": 1.5, "beta": 0.3}]}
    settings: dict[str, Any] = {"mode": mode or "momentary"}
    if mode == "trigger":
        settings.update({"attack": 0.06, "hold": 0.04, "release": 0.12})
    else:
        settings["filters"] = [{"type": "smooth", "rise": 0.1, "fall": 0.2}]
    return settings


def _inline(v: Any) -> Any:
    if isinstance(v, list):
        arr = tomlkit.array()
        for x in v:
            arr.append(_inline(x))
        return arr
    if isinstance(v, dict):
        t = tomlkit.inline_table()
        for k, x in v.items():
            t[k] = x
        return t
    return v


@contextmanager
def _folder_lock(folder: Path) -> Iterator[None]:
    """Hold an exclusive lock on the mapping's folder (flock on the folder itself: no lock file is
    left beside the user's map) while one binding is read, changed and renamed into place, so two
    `puppet learn` on one map (two boxes, two terminals) each add their binding; before, the last
    rename won and the other's binding was lost though both said 'added'. A folder that cannot be
    locked (missing, or a file system without flock) is written as before."""
    try:
        import fcntl

        fd = os.open(folder if str(folder) else ".", os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
    except (ImportError, OSError):
        yield
        return
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX)
        except OSError:
            pass
        yield
    finally:
        os.close(fd)  # closing the only descriptor releases the lock


def learn_binding(path: str | Path, control: str, device: str, target: str, kind: str,
                  mode: str | None = None, settings: dict[str, Any] | None = None) -> str:
    """Add (or retarget) the binding of `control` on `device` to `target` in the file at `path`
    (created if missing). Returns "added" or "updated". The result is parsed again before it
    replaces the file, so a learn never leaves a broken mapping behind."""
    p = Path(path)
    with _folder_lock(p.parent):
        return _learn_binding(p, control, device, target, kind, mode, settings)


def check_learn_file(path: str | Path) -> None:
    """Raise ConfigError now if bindings could not be learned into `path`: a file there that
    cannot be read as a mapping, or no folder to create it in. `puppet learn` asks this before
    the first touch (it told only after the performer had touched a control and named its target)."""
    p = Path(path)
    if p.exists():
        _read_doc(p)
    elif not p.parent.is_dir():
        raise ConfigError(f"{p}: cannot write the mapping file: {p.parent} is not a folder here; "
                          "make it, or give --map another path")


def _read_doc(p: Path) -> Any:
    try:
        text = read_text(p, "mapping file", 16 * 1024 * 1024)
    except BadFile as err:
        raise ConfigError(str(err)) from err
    parse_mapping(text, str(p))  # a file we cannot read is reported, never rewritten
    try:
        return tomlkit.parse(text)
    except (TOMLKitError, RecursionError, ValueError) as err:
        raise ConfigError(f"{p}: cannot read the mapping file: {quote(str(err), 80)}") from err


def _learn_binding(p: Path, control: str, device: str, target: str, kind: str, mode: str | None,
                   settings: dict[str, Any] | None) -> str:
    if p.exists():
        doc = _read_doc(p)
    else:
        doc = tomlkit.parse(NEW_FILE_HEADER)
        doc["version"] = 1
        doc["name"] = p.stem
    dev = device_key(device)
    bindings = doc.get("binding")
    if bindings is None:
        bindings = tomlkit.aot()
        doc["binding"] = bindings
    result = "added"
    for b in bindings:
        if b.get("control") == control and b.get("device", dev) == dev and "target" in b:
            b["target"] = target
            if mode is not None and kind in ("button", "key"):
                b["mode"] = mode
            for k, v in (settings or {}).items():
                b[k] = _inline(v)
            result = "updated"
            break
    else:
        t = tomlkit.table()
        t["control"] = control
        t["device"] = dev
        t["target"] = target
        for k, v in {**default_settings(kind, mode), **(settings or {})}.items():
            t[k] = _inline(v)
        t.add(tomlkit.nl())
        bindings.append(t)
    text = tomlkit.dumps(doc)
    parse_mapping(text, str(p))  # never write something we could not read back
    try:  # beside the file, synced, then renamed: a crash leaves the old file or the new one
        with atomic_write(p) as fh:
            fh.write(text)
    except (OSError, BadFile) as err:
        why = err.strerror if isinstance(err, OSError) else str(err).rsplit(": ", 1)[-1]
        raise ConfigError(f"{p}: cannot write the mapping file: {why}") from err
    return result
