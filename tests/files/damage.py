"""Damaged variants of a good file, the way disks, editors and scripts damage them: truncation at
every kind of boundary, byte flips, wrong types and extreme numbers per field, deep nesting, wrong
encodings, empty files. Deterministic for a seed. Used by the tests and benchmarks/damaged_files.py."""

from __future__ import annotations

import io
import json
import random
import re
import zipfile
from collections.abc import Callable, Iterator
from typing import Any

Variant = tuple[str, bytes]

#: What a field may be replaced by: wrong types, extreme and non-finite numbers, deep nesting.
BAD_VALUES: tuple[tuple[str, Any], ...] = (
    ("null", None), ("true", True), ("word", "seven"), ("empty-str", ""), ("list", [1, 2]),
    ("dict", {"a": 1}), ("zero", 0), ("neg", -1), ("neg-big", -1e308), ("big", 1e308),
    ("huge-int", 10**400), ("int64", 2**63), ("tiny", 5e-324), ("nan", float("nan")),
    ("inf", float("inf")), ("-inf", float("-inf")), ("long-str", "x" * 20000),
    ("deep", "DEEP"), ("terabyte", 10**13),
)
TEXT_TOKENS = ("", "nan", "inf", "-inf", "1e999", "-1", "0", "1e308", "9" * 400, "seven", "[", "]",
               "{", "}", '"', "[" * 3000, "\x00", "-0", "1_000", "0x10", "ÿ")


def _deep(n: int = 5000) -> str:
    return "[" * n + "]" * n


def dump_json(value: Any) -> str:
    """JSON text with NaN/Infinity tokens and the DEEP marker expanded to thousands of brackets."""
    text = json.dumps(value, allow_nan=True)
    return text.replace('"DEEP"', _deep())


def _paths(value: Any, prefix: tuple = ()) -> Iterator[tuple]:
    yield prefix
    if isinstance(value, dict):
        for k, v in value.items():
            yield from _paths(v, prefix + (k,))
    elif isinstance(value, list):
        for i, v in enumerate(value[:3]):
            yield from _paths(v, prefix + (i,))


def _replace(value: Any, path: tuple, new: Any) -> Any:
    if not path:
        return new
    out = dict(value) if isinstance(value, dict) else list(value)
    out[path[0]] = _replace(value[path[0]], path[1:], new)
    return out


def _delete(value: Any, path: tuple) -> Any:
    if len(path) == 1:
        out = dict(value) if isinstance(value, dict) else list(value)
        del out[path[0]]
        return out
    return _replace(value, path[:1], _delete(value[path[0]], path[1:]))


def json_fields(value: Any, rng: random.Random, n: int) -> Iterator[tuple[str, Any]]:
    """`n` variants of a JSON value: a field replaced by a bad value, or deleted."""
    paths = list(_paths(value))
    for _ in range(n):
        path = rng.choice(paths)
        if path and rng.random() < 0.15:
            yield f"del {'/'.join(map(str, path))}", _delete(value, path)
            continue
        name, bad = rng.choice(BAD_VALUES)
        yield f"{'/'.join(map(str, path)) or 'root'}={name}", _replace(value, path, bad)


def truncations(data: bytes, rng: random.Random, n: int) -> Iterator[Variant]:
    """Cuts at line ends, just before/after structural characters, and at random bytes."""
    cuts = {0, 1, len(data) - 1}
    cuts |= {m.end() for m in re.finditer(rb"\n", data)}
    cuts |= {m.start() for m in re.finditer(rb"\n", data)}
    for m in re.finditer(rb'[{}\[\],:"=]', data):
        cuts |= {m.start(), m.end()}
    cuts = sorted(c for c in cuts if 0 <= c < len(data))
    picked = cuts if len(cuts) <= n else sorted(rng.sample(cuts, n))
    for c in picked:
        yield f"cut@{c}", data[:c]


def flips(data: bytes, rng: random.Random, n: int) -> Iterator[Variant]:
    for _ in range(n):
        b = bytearray(data)
        k = rng.randrange(1, 4)
        for _ in range(k):
            i = rng.randrange(len(b))
            b[i] ^= 1 << rng.randrange(8)
        yield f"flip{k}", bytes(b)


def encodings(text: str) -> Iterator[Variant]:
    yield "empty", b""
    yield "blank", b"\n\n  \n"
    yield "utf16", text.encode("utf-16")
    yield "utf16-be", text.encode("utf-16-be")
    yield "latin1-ff", b"\xff\xfe\xfa" + text.encode("utf-8")
    yield "bom", b"\xef\xbb\xbf" + text.encode("utf-8")
    yield "nul", text.encode("utf-8").replace(b"\n", b"\n\x00", 1)
    yield "crlf", text.replace("\n", "\r\n").encode("utf-8")
    yield "binary", bytes(range(256)) * 4
    yield "deep-json", _deep(100_000).encode()


def text_tokens(text: str, rng: random.Random, n: int) -> Iterator[Variant]:
    """A whitespace-separated token of some line replaced by a bad token, or lines shuffled."""
    lines = text.splitlines()
    for _ in range(n):
        ls = list(lines)
        r = rng.random()
        i = rng.randrange(len(ls))
        if r < 0.1:
            j = rng.randrange(len(ls))
            ls[i], ls[j] = ls[j], ls[i]
            name = f"swap{i},{j}"
        elif r < 0.18:
            ls.insert(i, ls[i])
            name = f"dup{i}"
        else:
            toks = ls[i].split(" ")
            k = rng.randrange(len(toks))
            toks[k] = rng.choice(TEXT_TOKENS)
            ls[i] = " ".join(toks)
            name = f"tok{i}.{k}"
        yield name, ("\n".join(ls) + "\n").encode("utf-8", "surrogateescape")


def toml_values(text: str, rng: random.Random, n: int) -> Iterator[Variant]:
    """The right-hand side of a `key = value` line replaced by a bad TOML value."""
    bad = ("nan", "inf", "-inf", "1e308", "-1e308", "9" * 30, "9" * 5000, "-1", "0", '"seven"', "true",
           "[1, 2]", "{a = 1}", "[]", '""', "1e-320", "[" * 3000 + "]" * 3000, "x = ", "'''", '"' + "y" * 20000 + '"')
    lines = text.splitlines()
    spots = [i for i, ln in enumerate(lines) if re.match(r"\s*[\w.\"-]+\s*=", ln)]
    for _ in range(n):
        i = rng.choice(spots)
        ls = list(lines)
        key = ls[i].split("=", 1)[0]
        v = rng.choice(bad)
        ls[i] = f"{key}= {v}"
        yield f"line{i + 1}={v[:12]}", ("\n".join(ls) + "\n").encode()


def generic(data: bytes, rng: random.Random, n_cut: int, n_flip: int) -> Iterator[Variant]:
    yield from truncations(data, rng, n_cut)
    yield from flips(data, rng, n_flip)
    yield from encodings(data.decode("utf-8", "replace"))


# ------------------------------------------------------------------------------- per format

def recording_variants(good: bytes, seed: int = 14, n: int = 300) -> Iterator[Variant]:
    """A JSON Lines recording: header fields, record fields, whole lines, bytes."""
    rng = random.Random(seed)
    lines = good.decode().splitlines()
    header = json.loads(lines[0])
    for name, h in json_fields(header, rng, n // 3):
        yield "header:" + name, (dump_json(h) + "\n" + "\n".join(lines[1:]) + "\n").encode()
    body = list(range(1, len(lines)))
    for _ in range(n // 4):
        i = rng.choice(body)
        rec = json.loads(lines[i])
        name, r = next(json_fields(rec, rng, 1))
        ls = list(lines)
        ls[i] = dump_json(r)
        yield f"rec{i}:{name}", ("\n".join(ls) + "\n").encode()
    yield "header-only", (lines[0] + "\n").encode()
    yield "header-cut-newline", lines[0].encode()
    yield "header+end0", (lines[0] + '\n{"t":"end","ticks":0}\n').encode()
    yield "terabyte-end", (lines[0] + '\n{"t":"end","ticks":10000000000000}\n').encode()
    yield "terabyte-sync", (lines[0] + '\n{"t":"sync","tick":10000000000000}\n').encode()
    yield "huge-value-tick", (lines[0] + '\n{"t":"v","tick":99999999999,"v":{}}\n').encode()
    yield "jaw-1e308", (lines[0] + '\n{"t":"v","tick":0,"v":{"jaw":1e308}}\n{"t":"end","ticks":5}\n').encode()
    # lines past the reader's bounds (4 MB): a record, the header, junk after the header
    mid = len(lines) // 2
    long_rec = '{"t":"v","tick":0,"v":{"jaw":0.' + "1" * (5 << 20) + "}}"
    yield "long-record", ("\n".join(lines[:mid] + [long_rec] + lines[mid:]) + "\n").encode()
    yield "long-record-cut", ("\n".join(lines[:mid]) + "\n" + long_rec[:-2]).encode()
    yield "long-header", (lines[0][:-1] + ', "pad": "' + "x" * (5 << 20) + '"}\n' + "\n".join(lines[1:])).encode()
    yield "junk-after-header", (lines[0] + "\n").encode() + bytes(rng.randrange(256) for _ in range(1 << 16))
    yield "nul-line-after-header", (lines[0] + "\n").encode() + bytes(5 << 20)
    yield from generic(good, rng, n // 5, n // 5)


def jsonl_variants(good: bytes, seed: int = 14, n: int = 250) -> Iterator[Variant]:
    """JSON Lines (a journal): a field of some line replaced or deleted, a line doubled or dropped,
    and the byte-level damage."""
    rng = random.Random(seed)
    lines = good.decode().splitlines()
    for _ in range(n // 2):
        i = rng.randrange(len(lines))
        name, r = next(json_fields(json.loads(lines[i]), rng, 1))
        ls = list(lines)
        ls[i] = dump_json(r)
        yield f"line{i}:{name}", ("\n".join(ls) + "\n").encode()
    for i in range(len(lines)):
        yield f"drop{i}", ("\n".join(lines[:i] + lines[i + 1:]) + "\n").encode()
        yield f"twice{i}", ("\n".join(lines[:i + 1] + lines[i:]) + "\n").encode()
    yield from generic(good, rng, n // 4, n // 4)


def json_variants(good: bytes, seed: int = 14, n: int = 250) -> Iterator[Variant]:
    rng = random.Random(seed)
    value = json.loads(good)
    for name, v in json_fields(value, rng, n // 2):
        yield name, dump_json(v).encode()
    yield from generic(good, rng, n // 4, n // 4)


def toml_variants(good: bytes, seed: int = 14, n: int = 250) -> Iterator[Variant]:
    rng = random.Random(seed)
    text = good.decode()
    yield from toml_values(text, rng, n // 2)
    yield from text_tokens(text, rng, n // 6)
    yield from generic(good, rng, n // 6, n // 6)


def text_variants(good: bytes, seed: int = 14, n: int = 250) -> Iterator[Variant]:
    """Line-oriented text formats (curves, OBJ, DBC, ASCII PLY)."""
    rng = random.Random(seed)
    yield from text_tokens(good.decode(), rng, n // 2)
    yield from generic(good, rng, n // 4, n // 4)


def binary_variants(good: bytes, seed: int = 14, n: int = 200,
                    extra: Callable[[random.Random], Iterator[Variant]] | None = None) -> Iterator[Variant]:
    rng = random.Random(seed)
    yield "empty", b""
    yield from truncations(good, rng, n // 3)
    yield from flips(good, rng, n // 3)
    if extra is not None:
        yield from extra(rng)


def npz_bytes(arrays: dict[str, Any], raw: dict[str, bytes] | None = None) -> bytes:
    """An .npz archive of `arrays`, plus members given as raw .npy bytes (forged headers)."""
    import numpy as np

    buf = io.BytesIO()
    np.savez(buf, **arrays)
    if raw:
        with zipfile.ZipFile(buf, "a") as z:
            for name, data in raw.items():
                z.writestr(name + ".npy", data)
    return buf.getvalue()


def npy_forged(shape: tuple[int, ...], dtype: str = "<f8", body: bytes = b"\0" * 64) -> bytes:
    """A .npy member whose header promises `shape` but holds only `body`."""
    head = repr({"descr": dtype, "fortran_order": False, "shape": shape}).encode()
    head += b" " * (63 - (len(head) + 10) % 64) + b"\n"
    return b"\x93NUMPY\x01\x00" + len(head).to_bytes(2, "little") + head + body


def rig_variants(good: bytes, seed: int = 14, n: int = 200) -> Iterator[Variant]:
    """An .npz rig: bytes of the archive, fields of its JSON header, its arrays' types, shapes,
    values, and forged array headers that promise terabytes."""
    import numpy as np

    rng = random.Random(seed)
    with np.load(io.BytesIO(good), allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    header = json.loads(str(arrays["header"]))
    yield from binary_variants(good, seed, n // 3)
    for name, h in json_fields(header, rng, n // 3):
        a = dict(arrays)
        a["header"] = np.array(dump_json(h))
        yield "header:" + name, npz_bytes(a)
    keys = [k for k in arrays if k != "header"]
    bad_arrays = (
        ("nan", lambda a: np.full(a.shape, np.nan)), ("inf", lambda a: np.full(a.shape, np.inf)),
        ("neg", lambda a: np.full(a.shape, -1, dtype=a.dtype)), ("big", lambda a: np.full(a.shape, 2**31 - 1)),
        ("empty", lambda a: a[:0]), ("scalar", lambda a: np.array(3.0)), ("str", lambda a: np.array("x")),
        ("2d", lambda a: np.zeros((2, 2, 2))), ("bool", lambda a: np.ones(a.shape, bool)),
        ("half", lambda a: a[: max(1, len(a) // 2)] if a.ndim else a), ("obj", None),
        ("f1e300", lambda a: np.full(a.shape, 1e300)),
    )
    for _ in range(n // 3):
        k = rng.choice(keys)
        label, f = rng.choice(bad_arrays)
        if f is None:
            yield f"{k}=object", npz_bytes({x: v for x, v in arrays.items() if x != k},
                                           {k: npy_forged((3,), "|O", b"\0" * 24)})
            continue
        a = dict(arrays)
        try:
            a[k] = f(arrays[k])
        except (ValueError, TypeError, OverflowError):
            continue
        yield f"{k}={label}", npz_bytes(a)
    for k in ("vertices", "triangles", "jaw_weight", "header"):
        rest = {x: v for x, v in arrays.items() if x != k}
        yield f"{k}=forged-terabytes", npz_bytes(rest, {k: npy_forged((10**11, 3) if k != "header" else (), "<f8")})
    yield "missing-vertices", npz_bytes({x: v for x, v in arrays.items() if x != "vertices"})
