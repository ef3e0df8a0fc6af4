"""The integrator's prepared arrays shared by a machine's worker processes (`puppet.batch.shared`):
mapped from one file, the same bits as made, a damaged file made again, and a simulator copied for
a replay steps on the mapped arrays (not a private copy) to the very state a new simulator reaches."""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

import sim
from puppet import face_cache, live
from puppet.batch import shared, worker
from sim import prepared
from sim.face import targets as et


@pytest.fixture()
def store(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[shared.SharedStore]:
    """A shared store over the face cache in tmp_path; this process's memory emptied around it."""
    monkeypatch.setenv("PUPPET_CACHE_DIR", str(tmp_path))
    prepared._MEMO.clear()
    prepared.use_store(None)
    shared.install()
    face_cache.use_stepper_store()  # a face load re-installs the cache: the shared store stays in front
    s = prepared._STORE
    assert isinstance(s, shared.SharedStore) and isinstance(s.inner, face_cache.StepperStore)
    yield s
    prepared.use_store(None)
    prepared._MEMO.clear()
    worker.clear()


def _stepped(simulator: sim.Simulator, model: object) -> bytes:
    st = model.rest_state()  # type: ignore[attr-defined]
    for pose in ("AU45", "AU27+12"):
        ctl = et.pose_control(pose)
        for _ in range(8):
            simulator.step(st, ctl)
    return st.positions.tobytes() + st.velocities.tobytes() + np.asarray(st.contact).tobytes()


def test_arrays_round_trip_aligned_and_writable(tmp_path: Path) -> None:
    arrays = {"a": np.arange(7, dtype=np.int32), "b": np.linspace(0, 1, 12).reshape(3, 4),
              "h": np.array(1 / 120), "e": np.zeros(0, np.int64)}
    shared.write(tmp_path / "x.shared", arrays)
    back = shared.read(tmp_path / "x.shared")
    assert back.keys() == arrays.keys()
    for k, a in arrays.items():
        assert back[k].dtype == a.dtype and back[k].shape == a.shape and back[k].tobytes() == a.tobytes()
        assert back[k].ctypes.data % shared.ALIGN == 0 and back[k].flags.writeable
    back["b"][0, 0] = 5.0  # a private mapping: the file keeps its bytes
    assert shared.read(tmp_path / "x.shared")["b"][0, 0] == 0.0


@pytest.mark.parametrize("damage", ["truncate", "flip", "magic"])
def test_a_damaged_file_is_made_again(store: shared.SharedStore, damage: str) -> None:
    model = sim.face.default_model(0)
    want = _stepped(sim.Simulator(model, 1 / 120, wrinkles=False, method="implicit"), model)
    key = prepared.inputs_digest(model, 1 / 120)
    path = store.path(key)
    assert path.is_file()
    data = bytearray(path.read_bytes())
    if damage == "truncate":
        data = data[: len(data) // 2]
    elif damage == "flip":
        start = int.from_bytes(data[len(shared.MAGIC):len(shared.MAGIC) + 8], "little")
        data[start] ^= 0x40  # the first array's first byte
    else:
        data[:4] = b"JUNK"
    path.write_bytes(bytes(data))
    with pytest.raises(ValueError):
        shared.read(path)
    prepared._MEMO.clear()
    got = _stepped(sim.Simulator(model, 1 / 120, wrinkles=False, method="implicit"), model)
    assert got == want
    shared.read(path)  # written again, whole


def test_replays_step_on_the_mapped_arrays_to_the_same_bits(store: shared.SharedStore) -> None:
    model = live.load_face(None, 0, "procedural").model
    prepared.use_store(None)
    prepared._MEMO.clear()
    want = _stepped(sim.Simulator(model, 1 / 120, wrinkles=False, method="implicit"), model)
    prepared._MEMO.clear()
    shared.install()
    pristine = sim.Simulator(model, 1 / 120, wrinkles=False, method="implicit")
    mapped = shared.read(store.path(prepared.inputs_digest(model, 1 / 120)))
    a, b = (worker.copy.deepcopy(pristine, worker._kept(model, pristine)) for _ in range(2))
    for name in ("lu_lv", "bend_val", "fold_frame"):
        assert a._implicit.prepared[name] is b._implicit.prepared[name] is pristine._implicit.prepared[name]
        assert np.array_equal(a._implicit.prepared[name], mapped[name])
        assert not a._implicit.prepared[name].flags.owndata  # a view of the file's mapping
    assert _stepped(a, model) == want
    assert _stepped(b, model) == want


def test_another_process_maps_the_same_file(store: shared.SharedStore, tmp_path: Path) -> None:
    model = sim.face.default_model(0)
    sim.Simulator(model, 1 / 120, wrinkles=False, method="implicit")
    path = store.path(prepared.inputs_digest(model, 1 / 120))
    stamp = path.stat().st_mtime_ns
    code = ("import sim, sim.face; from puppet.batch import shared; from sim import prepared; shared.install();"
            "m = sim.face.default_model(0); s = sim.Simulator(m, 1/120, wrinkles=False, method='implicit');"
            "print(int(s._implicit.prepared['lu_lv'].flags.owndata))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         env={**__import__("os").environ, "PUPPET_CACHE_DIR": str(tmp_path)})
    assert out.stdout.strip() == "0"  # mapped, not loaded into its own memory
    assert path.stat().st_mtime_ns == stamp  # read, not written again


def test_workers_writing_at_once_keep_the_first_file(tmp_path: Path) -> None:
    """Two workers that miss at the same time both write; both then map the first one's file (one
    copy in memory), never two files in turn."""
    path = tmp_path / "x.shared"
    first, second = {"v": np.arange(4.0)}, {"v": np.arange(4.0) + 1}
    assert shared.write(path, first, replace=False)
    inode = path.stat().st_ino
    assert not shared.write(path, second, replace=False)
    assert path.stat().st_ino == inode and shared.read(path)["v"].tolist() == [0.0, 1.0, 2.0, 3.0]
    assert [p.name for p in tmp_path.iterdir()] == ["x.shared"]  # no temporary file left
