"""Find where a key sits in a TOML text, so a semantic error can name file:line:column the way a
syntax error does. tomllib keeps no positions, so this scans lines; it is used only on the error path."""

from __future__ import annotations

import re
from collections.abc import Sequence

PathItem = str | int


def _is_header(line: str) -> bool:
    return line.lstrip().startswith("[")


def _header_name(line: str) -> tuple[str, bool] | None:
    m = re.match(r"\s*(\[\[?)\s*([^\]]+?)\s*\]\]?", line)
    if not m:
        return None
    return m.group(2).replace(" ", "").replace('"', ""), m.group(1) == "[["


def locate(text: str, path: Sequence[PathItem]) -> tuple[int, int]:
    """(line, column), both 1-based, of the deepest part of `path` found in `text`.
    `path` is like ("binding", 3, "filters", 1, "rise") or ("combine", "jaw")."""
    lines = text.splitlines()
    start, end = 0, len(lines)
    best = (1, 1)
    rest = list(path)
    # 1. walk table headers: [a.b] or the n-th [[a]]
    prefix: list[str] = []
    while rest and isinstance(rest[0], str):
        name = ".".join(prefix + [rest[0]])
        idx = rest[1] if len(rest) > 1 and isinstance(rest[1], int) else None
        seen = -1
        found = None
        for i, line in enumerate(lines):
            h = _header_name(line)
            if h and h[0] == name:
                seen += 1
                if idx is None or seen == idx:
                    found = i
                    break
        if found is None:
            break
        start = found + 1
        end = next((j for j in range(start, len(lines)) if _is_header(lines[j])), len(lines))
        best = (found + 1, lines[found].index("[") + 1)
        prefix.append(rest.pop(0))
        if idx is not None:
            rest.pop(0)
            prefix = []  # keys inside an array-of-tables entry are relative to it
            break
    if not rest:
        return best
    # 2. the key line inside the table
    key = str(rest.pop(0))
    pat = re.compile(r"^\s*(" + re.escape(key) + r"|\"" + re.escape(key) + r"\")\s*=")
    row = next((i for i in range(start, end) if pat.match(lines[i])), None)
    if row is None:
        return best
    line = lines[row]
    col = line.index(key.split(".")[0]) + 1
    best = (row + 1, col)
    # 3. inside an inline array / table: the n-th `{` then a sub-key, possibly on later lines
    chunk_rows = [row]
    j = row + 1
    while j < end and not re.match(r"^\s*[A-Za-z0-9_\"-]+\s*=", lines[j]):
        chunk_rows.append(j)
        j += 1
    flat = [(r, c) for r in chunk_rows for c in range(len(lines[r]))]
    pos = next(k for k, (r, c) in enumerate(flat) if r == row and c == col - 1)
    if rest and isinstance(rest[0], int):
        n = rest.pop(0)
        braces = [k for k, (r, c) in enumerate(flat) if k > pos and lines[r][c] in "{"]
        if n < len(braces):
            pos = braces[n]
            best = (flat[pos][0] + 1, flat[pos][1] + 1)
    if rest and isinstance(rest[0], str):
        sub = rest.pop(0)
        text_flat = "".join(lines[r][c] for r, c in flat)
        m = re.compile(r"\b" + re.escape(sub) + r"\s*=").search(text_flat, pos)
        if m:
            r, c = flat[m.start()]
            best = (r + 1, c + 1)
    return best
