"""What a batch worker process keeps between tasks (`puppet.batch.worker`): a face is loaded once
per exact name (rig file bytes, spec, identity weights, resolution) and never served for another;
each replay's simulator is a copy of a prepared one and steps exactly as a new simulator does."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import sim
from puppet import live
from puppet.batch import worker


@pytest.fixture(autouse=True)
def empty_cache() -> Iterator[None]:
    from puppet import replay

    worker.clear()
    yield
    worker.clear()
    replay.use_loaders()


class Loads:
    """Stands in for puppet.live.load_face: a new object per call, remembering what was asked."""

    def __init__(self) -> None:
        self.asked: list[tuple[Any, ...]] = []

    def __call__(self, rig_path: str | None = None, resolution: int = 0, face: Any = None) -> Any:
        self.asked.append((rig_path, resolution, face))
        return type("Face", (), {"model": object(), "asked": (rig_path, resolution, face)})()


def test_each_identity_and_resolution_is_its_own_face(monkeypatch: pytest.MonkeyPatch) -> None:
    loads = Loads()
    monkeypatch.setattr(live, "load_face", loads)
    a = worker.load_face(None, 0, "ict?identity=1")
    assert worker.load_face(None, 0, "ict?identity=1") is a  # kept: loaded once
    b = worker.load_face(None, 0, "ict?identity=2")
    c = worker.load_face(None, 0, "ict")
    d = worker.load_face(None, 0, "procedural")
    e = worker.load_face(None, 1, "procedural")
    faces = [a, b, c, d, e]
    assert len({id(f) for f in faces}) == 5 and len(loads.asked) == 5
    assert [f.asked for f in faces] == loads.asked  # each is what was asked for, not a neighbour's


def test_a_rig_file_changed_in_place_is_loaded_again(tmp_path: Path) -> None:
    rig_path = tmp_path / "face.npz"
    model = live.load_face(None, 0, "procedural").model
    sim.save_rig(model.rig, rig_path)
    first = worker.load_face(str(rig_path))
    assert worker.load_face(str(rig_path)) is first
    rig = sim.load_rig(rig_path)
    rig.name = "renamed"
    sim.save_rig(rig, rig_path)  # the same path, other bytes
    second = worker.load_face(str(rig_path))
    assert second is not first and second.rig["name"] == "renamed" and first.rig["name"] != "renamed"


def test_only_a_few_faces_are_kept(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(live, "load_face", Loads())
    kept = [worker.load_face(None, 0, f"ict?identity={k}") for k in range(worker.MAX_FACES + 1)]
    assert worker.load_face(None, 0, f"ict?identity={worker.MAX_FACES}") is kept[-1]
    assert worker.load_face(None, 0, "ict?identity=0") is not kept[0]  # the oldest was dropped


def _run(simulator: Any, model: Any, ticks: int = 90) -> np.ndarray:
    state, control = model.rest_state(), sim.FaceControl(model)
    rng = np.random.default_rng(3)
    for k in range(ticks):
        if k % 30 == 0:
            control.values[...] = rng.uniform(0.0, 0.6, control.values.shape)
        simulator.step(state, control)
    return np.concatenate([state.positions.ravel(), state.surface.ravel()])


def test_copied_simulators_step_as_new_ones() -> None:
    model = live.load_face(None, 0, "procedural").model
    want = _run(sim.Simulator(model, 1 / 60), model)
    first = worker.new_simulator(model, 1 / 60)
    assert np.array_equal(_run(first, model), want)
    second = worker.new_simulator(model, 1 / 60)  # after a copy was used: still a fresh start
    assert second is not first and second.model is model
    assert np.array_equal(_run(second, model), want)
    assert worker.stats["simulators_built"] >= 1
    built = worker.stats["simulators_built"]
    worker.new_simulator(model, 1 / 30)  # another frame step: another simulator
    assert worker.stats["simulators_built"] == built + 1


def test_malloc_thresholds_are_set() -> None:
    assert worker.tune_malloc()


def test_longer_takes_are_submitted_with_higher_priority(tmp_path: Path) -> None:
    """Longest first: a task's priority is its take's size, so the long ones start first and the
    short ones fill the end of the batch."""
    from puppet.batch import run as batch_run
    from puppet.batch.plan import Output, load

    asked: list[tuple[str, int]] = []

    class Client:
        def submit(self, fn: Any, *args: Any, key: str, priority: int = 0) -> str:
            asked.append((key, priority))
            return key

    lengths = {"short": 10, "long": 400, "middle": 90}
    outs = []
    for name, lines in lengths.items():
        p = tmp_path / f"{name}.jsonl"
        p.write_text("".join(f'{{"t": {k}}}\n' for k in range(lines)))
        item = load(p)
        outs.append(Output(item, "export", f"{name}.pc2", name, {}))

    class NoFutures(Exception):
        pass

    def as_completed(_: Any) -> Any:
        raise NoFutures

    import dask.distributed

    real = dask.distributed.as_completed
    dask.distributed.as_completed = as_completed
    try:
        with pytest.raises(NoFutures):
            batch_run._submit_and_collect(Client(), outs, tmp_path, 0, batch_run.Report(), False)
    finally:
        dask.distributed.as_completed = real
    priority = {n: dict(asked)[k] for n, k in zip(lengths, [k for k, _ in asked])}
    assert priority["long"] > priority["middle"] > priority["short"] > 0
