"""The implicit integrator's prepared arrays (the factored matrix, the contact's Green's function)
kept in the face cache: a start from them steps to the same bits as a fresh build; an entry that is
damaged, foreign (another face's, another substep's) or inconsistent with its face is made again."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import sim.face
from puppet import face_cache
from sim import prepared
from sim.face import targets as et
from sim.integrator import Simulator

RATE = 120.0


@pytest.fixture(scope="module")
def face() -> object:
    return sim.face.default_model(0)


@pytest.fixture()
def store(tmp_path: Path, monkeypatch: pytest.MonkeyPatch):  # type: ignore[no-untyped-def]
    """The face cache's stepper store in tmp_path, this process's memory emptied before and after."""
    monkeypatch.setenv("PUPPET_CACHE_DIR", str(tmp_path))
    prepared._MEMO.clear()
    prepared._KEPT.clear()
    face_cache.use_stepper_store()
    yield face_cache.StepperStore(tmp_path)
    prepared.use_store(None)
    prepared._MEMO.clear()
    prepared._KEPT.clear()


class Counted:
    """sim.implicit.prepare, counting its calls (a call: the arrays were made, not loaded)."""

    def __init__(self, monkeypatch: pytest.MonkeyPatch) -> None:
        import sim.implicit

        self.calls, self._real = 0, sim.implicit.prepare
        monkeypatch.setattr(sim.implicit, "prepare", self)

    def __call__(self, model, h):  # type: ignore[no-untyped-def]
        self.calls += 1
        return self._real(model, h)


def _run(model: object) -> bytes:
    """A fresh process's view: nothing in memory, a simulator stepped through a blink and a smile
    with the jaw open (lid and lip contact, jaw-turned bending), its final state's bytes."""
    prepared._MEMO.clear()
    prepared._KEPT.clear()
    s = Simulator(model, 1.0 / RATE, wrinkles=False, method="implicit")  # type: ignore[arg-type]
    st = model.rest_state()  # type: ignore[attr-defined]
    for pose in ("AU45", "AU27+12"):
        ctl = et.pose_control(pose)
        for _ in range(12):
            s.step(st, ctl)
    return st.positions.tobytes() + st.velocities.tobytes() + np.asarray(st.contact).tobytes()


def test_a_start_from_the_cache_steps_to_the_same_bits(face: object, store: object, tmp_path: Path,
                                                        monkeypatch: pytest.MonkeyPatch) -> None:
    made = Counted(monkeypatch)
    fresh = _run(face)
    assert made.calls == 1 and len(list(tmp_path.glob("implicit-*.arrays"))) == 1
    assert not list(tmp_path.glob(".*tmp*"))
    cached = _run(face)
    assert made.calls == 1  # loaded, not made
    assert cached == fresh
    prepared.use_store(None)
    assert _run(face) == fresh  # and a build with no cache at all


def test_damaged_entries_are_made_again(face: object, store: object, tmp_path: Path,
                                        monkeypatch: pytest.MonkeyPatch) -> None:
    made = Counted(monkeypatch)
    fresh = _run(face)
    (path,) = tmp_path.glob("implicit-*.arrays")
    good = path.read_bytes()
    rng = np.random.default_rng(5)
    for _ in range(12):
        data = bytearray(good)
        if rng.random() < 0.3:
            data = data[: int(rng.integers(0, len(data)))]
        else:
            for at in rng.integers(0, len(data), 3):
                data[at] ^= 0xFF
        path.write_bytes(bytes(data))
        calls = made.calls
        assert _run(face) == fresh
        if path.read_bytes() != good:  # a variant that still loaded was one the checksums accept
            assert made.calls == calls
    assert made.calls > 5


def _rewrite(path: Path, edit) -> None:  # type: ignore[no-untyped-def]
    """Rewrite an entry with edit(arrays) applied and its checksums made consistent again, so only
    the checks against the face can catch it."""
    from puppet import mapped

    arrays = {k: np.array(a) for k, a in mapped.read(path).items()}
    edit(arrays)
    mapped.write(path, arrays)


@pytest.mark.parametrize("edit", [
    lambda a: a.update(h=np.array(1.0 / 60.0)),  # another substep's factor
    lambda a: a.update(lu_perm_c=a["lu_perm_c"][::-1].copy() * 0),  # not a permutation
    lambda a: a.update(lu_r_idx=a["lu_r_idx"] + 10**6),  # an index past the matrix
    lambda a: a.update(c_loc=np.full(3, -1, np.int64)),  # another face's contact
    lambda a: a.update(lu_u_diag=a["lu_u_diag"] * np.nan),
    lambda a: a.pop("c_green"),
], ids=["substep", "permutation", "index", "contact", "nan", "missing"])
def test_an_entry_that_does_not_match_its_face_is_made_again(edit, face: object, store: object,  # type: ignore[no-untyped-def]
                                                              tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    made = Counted(monkeypatch)
    fresh = _run(face)
    (path,) = tmp_path.glob("implicit-*.arrays")
    _rewrite(path, edit)
    assert _run(face) == fresh and made.calls == 2


def test_another_faces_entry_is_not_used(face: object, store: object, tmp_path: Path,
                                         monkeypatch: pytest.MonkeyPatch) -> None:
    """The key follows what the arrays are made from: another substep, or the same face with its
    lid bending changed (its hash changes too), is another entry; a valid entry of one copied under
    the other's name is refused by its recorded inputs."""
    import dataclasses

    made = Counted(monkeypatch)
    fresh = _run(face)
    stiffer = dataclasses.replace(face, params=dataclasses.replace(face.params, lid_bending=2 * face.params.lid_bending))  # type: ignore[attr-defined]
    assert prepared.inputs_digest(stiffer, 1 / RATE) != prepared.inputs_digest(face, 1 / RATE)
    assert prepared.inputs_digest(face, 1 / 60) != prepared.inputs_digest(face, 1 / RATE)
    _run(stiffer)
    assert made.calls == 2
    a, b = (store.path(prepared.inputs_digest(m, 1 / RATE)) for m in (face, stiffer))  # type: ignore[attr-defined]
    a.write_bytes(b.read_bytes())
    assert _run(face) == fresh and made.calls == 3


def test_only_the_most_recently_used_steppers_are_kept(face: object, store: object, tmp_path: Path) -> None:
    """Each tick rate (substep) of a face is an entry; the folder keeps KEEP_STEPPERS of them, the
    ones used last, beside the faces' own entries."""
    import os

    rates = [60.0, 90.0, 120.0, 150.0, 180.0, 240.0]
    for k, rate in enumerate(rates):
        prepared._MEMO.clear()
        Simulator(face, 1.0 / rate, wrinkles=False, method="implicit")  # type: ignore[arg-type]
        path = store.path(prepared.inputs_digest(face, 1.0 / rate))  # type: ignore[attr-defined]
        os.utime(path, (1000.0 + k, 1000.0 + k))  # distinct ages, whatever the clock's resolution
    kept = sorted(tmp_path.glob("implicit-*.arrays"))
    newest = {store.path(prepared.inputs_digest(face, 1.0 / r)) for r in rates[-face_cache.KEEP_STEPPERS:]}  # type: ignore[attr-defined]
    assert len(kept) == face_cache.KEEP_STEPPERS and set(kept) == newest


def test_the_jaws_grid_is_kept_beside_the_stepper(face: object, store: object, tmp_path: Path,
                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    """The jaw's responses and poses at the grid's openings (66 solves and 33 poses a start) are
    made by the first start and read back by the next, which steps the opening jaw to the same bits;
    a damaged or misshapen entry is made again."""
    import sim.integrator

    made, real = [], sim.integrator._jaw_grid
    monkeypatch.setattr(sim.integrator, "_jaw_grid", lambda s: made.append(1) or real(s))
    fresh = _run(face)
    (path,) = tmp_path.glob("jaw-*.arrays")
    assert len(made) == 1 and len(list(tmp_path.glob("implicit-*.arrays"))) == 1
    assert _run(face) == fresh and len(made) == 1  # read back, not made
    good = path.read_bytes()
    data = bytearray(good)
    data[len(data) // 2] ^= 0xFF
    path.write_bytes(bytes(data))
    assert _run(face) == fresh and len(made) == 2
    path.write_bytes(good)
    _rewrite(path, lambda a: a.update(pose=a["pose"][:, :, :-1].copy()))  # another face's poses
    assert _run(face) == fresh and len(made) == 3
    prepared.use_store(None)
    assert _run(face) == fresh and len(made) == 4  # and with no cache at all
