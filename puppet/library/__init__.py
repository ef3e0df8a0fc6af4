"""The take library: every recording indexed in one SQLite file (the user's data folder, or
`--library PATH`), searchable by text, performer, date, tag and expression. See docs/studio.md."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from puppet.errors import PuppetError
from puppet.library.store import Library, default_path


def library_path(arg: str | None) -> Path | None:
    """--library PATH, else the default place (None: the library is off, PUPPET_LIBRARY=off)."""
    return Path(arg) if arg else default_path()


def open_library(arg: str | None) -> Library:
    """The library for a `puppet takes` / `puppet batch` command."""
    path = library_path(arg)
    if path is None:
        raise PuppetError("the take library is off (PUPPET_LIBRARY=off); pass --library PATH")
    return Library(path)


def complete_died(lib: Library, say: Callable[[str], None] | None = None) -> None:
    """Complete the entries of takes whose show died (as `puppet takes check` does) before they
    are listed or selected; `say` hears one line per take completed or found damaged."""
    from puppet.library.upkeep import complete_died as complete

    rep = complete(lib)
    if say is not None:
        for i in rep.crashed:
            say(f"take {i}: its show died while recording; its entry is completed from what the file holds")
        for i, why in rep.damaged:
            say(f"take {i}: its show died and its file no longer holds it ({why}); marked damaged")


def begin_recording(record: str | Path, header: dict[str, Any], performer: str | None, tags: list[str],
                    arg: str | None, warn: Callable[[str], None], kept: str | Path | None = None) -> int | None:
    """Register the take `puppet live` begins recording (its header written): path, date, face and
    identity, devices, performer, `tags`; `register_recording` completes it when the show ends,
    `puppet takes check` if the show dies first. Never raises (the show goes on whatever the
    library does). `kept`: where the take `record` held before was moved (session.keep_previous);
    the library follows it there, tags and notes with it. Returns the take's id, or None."""
    return _on_library(record, arg, warn, kept, lambda lib: lib.begin(record, header, performer=performer, tags=tags),
                       lambda path, err: f"the take {record} is being recorded but was not added to the library "
                       f"{path}: {err}; it is added when the show ends")


def register_recording(record: str | Path, performer: str | None, arg: str | None,
                       warn: Callable[[str], None], kept: str | Path | None = None,
                       tags: list[str] | tuple[str, ...] = ()) -> int | None:
    """Complete the library's entry of a take just recorded by `puppet live` (duration, hash,
    markers; registering it if its start was not); never raises (a show's recording is safe on
    disk whatever the library does). `kept`: as for `begin_recording`. Returns the take's id, or None."""
    return _on_library(record, arg, warn, kept, lambda lib: lib.register(record, performer=performer, tags=tags),
                       lambda path, err: f"the take {record} is safe but was not added to the library {path}: {err}")


def _on_library(record: str | Path, arg: str | None, warn: Callable[[str], None], kept: str | Path | None,
                act: Callable[[Library], int], failed: Callable[[Path, Exception], str]) -> int | None:
    """`act` on the library `arg` names (none: nothing), after following the take kept aside from
    `record` to `kept`; whatever goes wrong is `failed`'s one warning, never an error: the library
    must never cost the performer the show or the take. Returns `act`'s take id, or None."""
    path = library_path(arg)
    if path is None:
        return None
    try:
        with Library(path, warn=warn) as lib:
            if kept is not None:
                lib.follow(record, kept)
            return act(lib)
    except Exception as err:
        warn(failed(path, err))
        return None
