"""The compiled-face cache: a warm start loads the same face bit for bit; any damaged, foreign or
inconsistent entry is ignored and rebuilt (generated variants, fixed seed); the key follows the
face-building code; the cache lives where the docs say."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

import sim.face
from puppet import face_cache, live
from puppet.face_cache import CacheEntryError, cached_model, load_entry

WHAT = b"default-face:0"


@pytest.fixture(scope="module")
def fresh() -> object:
    return sim.face.default_model(0)


def _same(a: object, b: object) -> None:
    arrays_a, scalars_a = face_cache._split(a)
    arrays_b, scalars_b = face_cache._split(b)
    assert scalars_a == scalars_b and set(arrays_a) == set(arrays_b)
    for k in arrays_a:
        assert arrays_a[k].dtype == arrays_b[k].dtype and np.array_equal(arrays_a[k], arrays_b[k]), k
    assert a.params == b.params and a.rig.name == b.rig.name  # type: ignore[attr-defined]


class Builds:
    """A build function that counts its calls and returns the fresh model."""

    def __init__(self, model: object) -> None:
        self.model, self.calls = model, 0

    def __call__(self) -> object:
        self.calls += 1
        return self.model


def test_warm_load_is_the_same_face_and_steps_bit_identically(fresh: object, tmp_path: Path,
                                                             monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("PUPPET_CACHE_DIR", str(tmp_path))
    build = Builds(fresh)
    first = cached_model(WHAT, build)
    assert first is fresh and build.calls == 1
    assert sorted(p.suffix for p in tmp_path.iterdir()) == [".arrays", ".npz"]
    assert not list(tmp_path.glob("*.tmp*"))  # written beside, renamed into place
    warm = cached_model(WHAT, build)
    assert build.calls == 1 and warm is not fresh
    _same(warm, fresh)
    states = []
    for model in (fresh, warm):
        s = sim.Simulator(model, 1 / 60)
        st, ctl = model.rest_state(), sim.FaceControl(model)  # type: ignore[attr-defined]
        ctl.values[model.channel_index["jaw"]] = 0.7  # type: ignore[attr-defined]
        for _ in range(5):
            s.step(st, ctl)
        states.append(st.positions.tobytes())
    assert states[0] == states[1]


def _entry(directory: Path, fresh: object) -> str:
    face_cache.save_entry(directory, face_cache.entry_key(WHAT), fresh, with_rig=True)
    return face_cache.entry_key(WHAT)


def _rewrite(path: Path, edit) -> None:  # type: ignore[no-untyped-def]
    """Rewrite an entry's npz with edit(arrays, meta) applied and its checksums made consistent
    again, so only the structural checks can catch it."""
    with np.load(path, allow_pickle=False) as data:
        arrays = {k: data[k] for k in data.files}
    meta = json.loads(str(arrays.pop("meta")))
    edit(arrays, meta)
    meta["arrays"] = face_cache._array_digest(arrays)
    np.savez(path, meta=np.array(json.dumps(meta)), **arrays)


def _set(name: str, fn):  # type: ignore[no-untyped-def]
    def edit(arrays: dict, meta: dict) -> None:
        a = arrays[name].copy()
        fn(a)
        arrays[name] = a
    return edit


STRUCTURAL = {
    "spring index past the end": _set("a_spring_indices", lambda a: a.__setitem__((0, 1), 10**6)),
    "negative spring index": _set("a_spring_indices", lambda a: a.__setitem__((3, 0), -1)),
    "eye index 2": _set("a_eye_contact_eye", lambda a: a.__setitem__(0, 2)),
    "NaN rest": _set("a_rest", lambda a: a.__setitem__((0, 0), np.nan)),
    "moved rest": _set("a_rest", lambda a: a.__setitem__((0, 0), a[0, 0] + 1e-9)),
    "zero mass": _set("a_mass", lambda a: a.__setitem__(5, 0.0)),
    "infinite damping": _set("a_damping", lambda a: a.__setitem__(5, np.inf)),
    "muscle column past the end": _set("mm_indices", lambda a: a.__setitem__(0, 10**6)),
    "muscle indices as floats": lambda arrays, meta: arrays.__setitem__("mm_indices",
                                                                        arrays["mm_indices"].astype(np.float64)),
    "muscle forces as float32": lambda arrays, meta: arrays.__setitem__("mm_data", arrays["mm_data"].astype(np.float32)),
    "muscle row pointers of another width": lambda arrays, meta: arrays.__setitem__(
        "mm_indptr", arrays["mm_indptr"].astype(np.int64 if arrays["mm_indices"].dtype == np.int32 else np.int32)),
    "muscle row pointer going back": _set("mm_indptr", lambda a: a.__setitem__(len(a) // 2, a[len(a) // 2 - 1] - 1)),
    "muscle indices in 2-D": lambda arrays, meta: arrays.__setitem__("mm_indices", arrays["mm_indices"][None, :]),
    "short spring array": lambda arrays, meta: arrays.__setitem__("a_spring_k_low", arrays["a_spring_k_low"][:-1]),
    "missing array": lambda arrays, meta: arrays.pop("a_held"),
    "extra array": lambda arrays, meta: arrays.__setitem__("a_bogus", np.zeros(3)),
    "text array": lambda arrays, meta: arrays.__setitem__("a_mass", np.array(["x"] * len(arrays["a_mass"]))),
    "other key": lambda arrays, meta: meta.__setitem__("key", "0" * 32),
    "other version": lambda arrays, meta: meta.__setitem__("version", 99),
    "other format": lambda arrays, meta: meta.__setitem__("format", "something"),
    "other rig hash": lambda arrays, meta: meta["scalars"].__setitem__("hash", "ffff"),
    "params as text": lambda arrays, meta: meta.__setitem__("params", "soft"),
    "unknown param": lambda arrays, meta: meta["params"].__setitem__("bogus", 1.0),
    "stiffer skin": lambda arrays, meta: meta["params"].__setitem__("sheet_modulus", 1.0),
    "scalar of the wrong type": lambda arrays, meta: meta["scalars"].__setitem__("n_edge_springs", [1]),
    "matrix shape": lambda arrays, meta: meta.__setitem__("mm_shape", [3, 3]),
    "rig checksum": lambda arrays, meta: meta.__setitem__("rig_sha", "0" * 64),
    "meta a list": lambda arrays, meta: (meta.clear(), meta.update({"x": [[[[[]]]]]})),
}


@pytest.mark.parametrize("name", sorted(STRUCTURAL))
def test_inconsistent_entry_is_refused_then_rebuilt(name: str, fresh: object, tmp_path: Path,
                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("PUPPET_CACHE_DIR", str(tmp_path))
    key = _entry(tmp_path, fresh)
    _rewrite(tmp_path / f"{key}.npz", STRUCTURAL[name])
    with pytest.raises(CacheEntryError):
        load_entry(tmp_path, key, None)
    build = Builds(fresh)
    assert cached_model(WHAT, build) is fresh and build.calls == 1
    _same(load_entry(tmp_path, key, None), fresh)  # the rebuilt entry is good again


def _variants(data: bytes, rng: np.random.Generator, n: int) -> list[bytes]:
    out = [b"", data[:1], data[:30], data[:-1]]
    cuts = rng.integers(1, len(data), n // 3)
    out += [data[:c] for c in cuts]
    for _ in range(n - len(out)):
        b = bytearray(data)
        for pos in rng.integers(0, len(b), rng.integers(1, 9)):
            b[pos] ^= 1 << int(rng.integers(0, 8))
        out.append(bytes(b))
    return out


def test_damaged_entries_are_ignored_and_rebuilt(fresh: object, tmp_path: Path,
                                                monkeypatch: pytest.MonkeyPatch) -> None:
    """Truncations and bit flips of both files of an entry (fixed seed): every variant gives the
    same face as a fresh build, never an exception; a variant that still loads is the same face."""
    monkeypatch.setenv("PUPPET_CACHE_DIR", str(tmp_path))
    key = _entry(tmp_path, fresh)
    model_path, rig_path = tmp_path / f"{key}.npz", tmp_path / f"{key}.rig.arrays"
    good = {model_path: model_path.read_bytes(), rig_path: rig_path.read_bytes()}
    rng = np.random.default_rng(14)
    build = Builds(fresh)
    n_loaded = 0
    for target in (model_path, rig_path):
        for variant in _variants(good[target], rng, 150):
            for p, data in good.items():
                p.write_bytes(variant if p == target else data)
            calls = build.calls
            got = cached_model(WHAT, build)
            if build.calls == calls:  # the damage missed everything that matters (e.g. zip padding)
                n_loaded += 1
                _same(got, fresh)
            else:
                assert got is fresh
    assert n_loaded < 30  # nearly every variant was caught
    model_path.unlink()
    assert cached_model(WHAT, build) is fresh  # a missing file too


def test_a_foreign_entry_under_our_name_is_not_used(fresh: object, tmp_path: Path,
                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    """Another key's valid entry copied under ours (another face or program version): refused."""
    monkeypatch.setenv("PUPPET_CACHE_DIR", str(tmp_path))
    other = face_cache.entry_key(b"default-face:7")
    face_cache.save_entry(tmp_path, other, fresh, with_rig=True)
    key = face_cache.entry_key(WHAT)
    for suffix in (".npz", ".rig.arrays"):
        shutil.copy(tmp_path / f"{other}{suffix}", tmp_path / f"{key}{suffix}")
    with pytest.raises(CacheEntryError, match="foreign"):
        load_entry(tmp_path, key, None)


def test_key_follows_every_source_file_of_the_face_code(tmp_path: Path) -> None:
    root = Path(sim.__file__).resolve().parent
    copy = tmp_path / "sim"
    shutil.copytree(root, copy, ignore=shutil.ignore_patterns("__pycache__"))
    base = face_cache.source_digest(copy)
    assert base == face_cache.source_digest(root)
    (copy / "face" / "shape.py").write_text((copy / "face" / "shape.py").read_text() + "\n# tweak\n")
    tweaked = face_cache.source_digest.__wrapped__(copy)
    assert tweaked != base
    (copy / "face" / "extra").mkdir()
    (copy / "face" / "extra" / "head.py").write_text("X = 1\n")  # a new module (the face reshaped)
    added = face_cache.source_digest.__wrapped__(copy)
    assert added not in (base, tweaked)
    scan = copy / "face" / "scan" / "ict_head.npz"
    data = bytearray(scan.read_bytes())
    data[len(data) // 2] ^= 0xFF  # the scanned head's data changed
    scan.write_bytes(bytes(data))
    assert face_cache.source_digest.__wrapped__(copy) not in (base, tweaked, added)


def test_cache_location_and_off(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, fresh: object,
                                capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.delenv("PUPPET_CACHE_DIR", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert face_cache.cache_dir() == tmp_path / "xdg" / "facepuppet" / "faces"
    monkeypatch.delenv("XDG_CACHE_HOME")
    assert face_cache.cache_dir() == Path.home() / ".cache" / "facepuppet" / "faces"
    monkeypatch.setenv("PUPPET_CACHE_DIR", "off")
    assert face_cache.cache_dir() is None
    build = Builds(fresh)
    cached_model(WHAT, build)
    cached_model(WHAT, build)
    assert build.calls == 2
    blocker = tmp_path / "a-file"
    blocker.write_text("not a folder")
    monkeypatch.setenv("PUPPET_CACHE_DIR", str(blocker / "faces"))
    assert cached_model(WHAT, build) is fresh  # cannot write: built, one warning line
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "cannot cache" in err[0] and "PUPPET_CACHE_DIR" in err[0]


def test_rig_file_faces_are_cached_by_the_file_bytes(fresh: object, tmp_path: Path,
                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("PUPPET_CACHE_DIR", str(tmp_path / "cache"))
    rig_path = tmp_path / "face.npz"
    sim.save_rig(fresh.rig, rig_path)  # type: ignore[attr-defined]
    a = live.load_face(str(rig_path))
    entries = sorted(p.name for p in (tmp_path / "cache").iterdir())
    assert len(entries) == 1  # a user's rig is read from the user's file, not copied
    b = live.load_face(str(rig_path))
    assert a.model is not b.model and a.rig["hash"] == b.rig["hash"] == fresh.hash  # type: ignore[attr-defined]
    _same(a.model, b.model)
    rig = sim.load_rig(rig_path)
    rig.name = "renamed"
    sim.save_rig(rig, rig_path)
    live.load_face(str(rig_path))
    assert len(list((tmp_path / "cache").iterdir())) == 2  # another file, another entry


def test_only_the_most_recently_used_entries_are_kept(fresh: object, tmp_path: Path,
                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    """Each edit of the face code makes a new entry: the folder keeps the last KEEP_ENTRIES used."""
    import os

    monkeypatch.setenv("PUPPET_CACHE_DIR", str(tmp_path))
    build = Builds(fresh)
    n = face_cache.KEEP_ENTRIES + 3
    for i in range(n):
        cached_model(f"face {i}".encode(), build)
        key = face_cache.entry_key(f"face {i}".encode())
        os.utime(tmp_path / f"{key}.npz", (1000.0 + i, 1000.0 + i))  # distinct use times
    cached_model(b"face 0", build)  # gone: rebuilt, now the newest
    assert build.calls == n + 1
    os.utime(tmp_path / f"{face_cache.entry_key(b'face 0')}.npz", (5000.0, 5000.0))
    cached_model(b"face 1", build)  # evicted too: rebuilt, and the oldest goes
    kept = {p.name for p in tmp_path.iterdir()}
    assert len(kept) == 2 * face_cache.KEEP_ENTRIES
    for i in (0, 1, n - 1):
        key = face_cache.entry_key(f"face {i}".encode())
        assert f"{key}.npz" in kept and f"{key}.rig.arrays" in kept
    assert f"{face_cache.entry_key(b'face 3')}.npz" not in kept


def test_the_cached_muscle_matrix_is_the_built_one_without_scipy(fresh: object, tmp_path: Path,
                                                                monkeypatch: pytest.MonkeyPatch) -> None:
    """A face from the cache carries its muscle matrix as plain CSR arrays (the kernels read
    nothing else); asked for anything more it answers as the built scipy matrix does."""
    from sim.csr import CsrArrays

    monkeypatch.setenv("PUPPET_CACHE_DIR", str(tmp_path))
    cached_model(WHAT, Builds(fresh))
    warm = cached_model(WHAT, Builds(fresh))
    mm, built = warm.muscle_matrix, fresh.muscle_matrix  # type: ignore[attr-defined]
    assert isinstance(mm, CsrArrays) and mm.shape == built.shape and mm.nnz == built.nnz
    dense = built.toarray()
    assert np.array_equal(mm.toarray(), dense)
    rng = np.random.default_rng(3)
    v = rng.uniform(0, 1, built.shape[1])
    assert np.array_equal(mm @ v, built @ v)
    assert np.array_equal((mm.T @ np.ones(built.shape[0])), built.T @ np.ones(built.shape[0]))
    assert np.array_equal(mm[:, 1].toarray(), built[:, 1].toarray())


def _same_shell(a: object, b: object) -> None:
    for name in face_cache._SHELL_ARRAYS:
        x, y = getattr(a, name), getattr(b, name)
        assert x.dtype == y.dtype and np.array_equal(x, y), name
    assert a.head_triangles == b.head_triangles  # type: ignore[attr-defined]


@pytest.mark.timeout(900)  # a hang guard: ~120 rebuilds of the shell (~50 s quiet) ran past 300 s at load 30
def test_the_head_shell_is_kept_beside_the_faces_and_damaged_copies_are_rebuilt(
        fresh: object, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The default face's held head (~0.4 s to build) is built once and read back by the next
    process (here: a cleared in-process memo); truncated or bit-flipped copies (fixed seed) never
    raise and give the built shell, a copy that still loads is the same shell."""
    from sim.face import head as face_head

    rig = fresh.rig  # type: ignore[attr-defined]
    built = face_head.head_shell(rig.mesh)
    store = face_cache.HeadShellStore(tmp_path)
    monkeypatch.setattr(face_head, "_STORE", store)
    monkeypatch.setattr(face_head, "_SHELLS", {})
    calls = []
    real = face_head.head_shell
    monkeypatch.setattr(face_head, "head_shell", lambda mesh: calls.append(1) or real(mesh))
    first = face_head.shell_for(rig)
    (path,) = tmp_path.glob("head-*.npz")
    assert len(calls) == 1 and not list(tmp_path.glob(".*tmp*"))
    _same_shell(first, built)
    face_head._SHELLS.clear()
    again = face_head.shell_for(rig)
    assert len(calls) == 1 and again is not first  # read from the file, not built
    _same_shell(again, built)
    good = path.read_bytes()
    rng = np.random.default_rng(15)
    loaded = 0
    for variant in _variants(good, rng, 120):
        path.write_bytes(variant)
        face_head._SHELLS.clear()
        n = len(calls)
        got = face_head.shell_for(rig)
        _same_shell(got, built)
        loaded += len(calls) == n
    assert loaded < 25  # nearly every damaged copy was caught and rebuilt


def test_a_head_shell_that_does_not_fit_its_mask_is_refused(fresh: object) -> None:
    from dataclasses import replace

    from sim.face import head as face_head

    mesh = fresh.rig.mesh  # type: ignore[attr-defined]
    shell = face_head.head_shell(mesh)
    face_head.check_shell(shell, mesh)
    bad_tri = shell.triangles.copy()
    bad_tri[0, 0] = len(shell.vertices)
    bad_mask = shell.ring_mask.copy()
    bad_mask[0] = len(mesh.vertices)
    nan = shell.vertices.copy()
    nan[3, 1] = np.nan
    for broken in (replace(shell, triangles=bad_tri), replace(shell, ring_mask=bad_mask),
                   replace(shell, vertices=nan), replace(shell, col_w=shell.col_w[:-1]),
                   replace(shell, head_triangles=len(shell.triangles) + 1)):
        with pytest.raises(ValueError):
            face_head.check_shell(broken, mesh)
