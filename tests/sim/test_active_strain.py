"""Active strain (sim.active_strain, FaceRig.strain, sim.face.scan.strain_fit) on the synthetic face:
its forces are internal, a rig file keeps it and a rig without it keeps its hash, a contraction
shortens the skin along the fibre on the simulator, and the fit's gradient and written fields are
its linear model's."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from sim.active_strain import strain_force
from sim.build import compile_model
from sim.model import FaceRig
from sim.rig import RigFileError, load_rig, save_rig


def _strain(model, channel: str, xx: float) -> np.ndarray:  # type: ignore[no-untyped-def]
    """(N, 6) a strain of `xx` along x over the skin the channel's muscle pulls."""
    col = model.muscle_matrix[:, model.channel_index[channel]].toarray().reshape(-1, 3)
    zone = np.linalg.norm(col, axis=1) > 1e-3 * np.linalg.norm(col, axis=1).max()
    e = np.zeros((model.n_vertices, 6))
    e[zone, 0] = xx
    return e


def test_strain_forces_are_internal(synth_model) -> None:  # type: ignore[no-untyped-def]
    """Each spring pushes its two ends apart or together: no net force, no net torque."""
    rng = np.random.default_rng(3)
    e = rng.uniform(-0.3, 0.3, (synth_model.n_vertices, 6))
    rest = np.asarray(synth_model.rest)
    f = strain_force(rest, synth_model.spring_indices, synth_model.spring_rest_length, synth_model.spring_k_low, e)
    scale = np.abs(f).sum()
    assert scale > 0
    assert np.abs(f.sum(axis=0)).max() < 1e-9 * scale
    assert np.abs(np.cross(rest, f).sum(axis=0)).max() < 1e-9 * scale * np.abs(rest).max()


def test_strain_round_trips_and_a_rig_without_keeps_its_hash(synth_rig: FaceRig, synth_model,  # type: ignore[no-untyped-def]
                                                              tmp_path: Path) -> None:
    ch = "zygomaticus_major_l"
    e = _strain(synth_model, ch, -0.2)
    rig = replace(synth_rig, strain={ch: e})
    save_rig(rig, tmp_path / "s.npz")
    back = load_rig(tmp_path / "s.npz")
    assert set(back.strain) == {ch} and np.array_equal(back.strain[ch], e)
    strained = compile_model(back)
    assert strained.hash != synth_model.hash
    assert compile_model(replace(back, strain={})).hash == synth_model.hash
    plain_cols = synth_model.muscle_matrix.toarray()
    cols = strained.muscle_matrix.toarray()
    i = synth_model.channel_index[ch]
    assert np.array_equal(np.delete(cols, i, axis=1), np.delete(plain_cols, i, axis=1))
    assert not np.allclose(cols[:, i], plain_cols[:, i])
    save_rig(synth_rig, tmp_path / "plain.npz")
    assert "strain" not in json.loads(str(np.load(tmp_path / "plain.npz")["header"]))


def test_a_strain_out_of_range_is_one_clear_line(synth_rig: FaceRig, tmp_path: Path) -> None:
    n = len(synth_rig.mesh.vertices)
    save_rig(replace(synth_rig, strain={"zygomaticus_major_l": np.full((n, 6), 2.0)}), tmp_path / "bad.npz")
    with pytest.raises(RigFileError, match=r"bad\.npz: active strain of .zygomaticus_major_l. must lie in -1\.\.1"):
        load_rig(tmp_path / "bad.npz")


def test_a_contraction_shortens_the_skin_along_the_fibre(synth_rig: FaceRig, synth_model) -> None:  # type: ignore[no-untyped-def]
    """On the simulator, a channel whose tissue shortens along x (strain -0.2) leaves the springs
    along x in its zone shorter than the same channel's pull alone; lengthening leaves them longer."""
    from sim.fit.basis import Settler

    ch = "zygomaticus_major_l"
    springs = np.asarray(synth_model.spring_indices)
    rest = np.asarray(synth_model.rest)
    d = rest[springs[:, 0]] - rest[springs[:, 1]]
    along = np.abs(d[:, 0]) > 0.9 * np.linalg.norm(d, axis=1)
    zone = np.any(_strain(synth_model, ch, 1.0) != 0, axis=1)
    sel = along & zone[springs].all(axis=1)
    assert sel.sum() > 5

    def lengths(xx: float) -> float:
        model = synth_model if xx == 0.0 else compile_model(replace(synth_rig, strain={ch: _strain(synth_model, ch, xx)}))
        st = Settler(model)
        x = st.pose(st.values_for({ch: 1.0}))
        return float(np.linalg.norm(x[springs[sel, 0]] - x[springs[sel, 1]], axis=1).mean())

    pull, shorter, longer = lengths(0.0), lengths(-0.2), lengths(0.2)
    assert shorter < pull - 0.02 * np.linalg.norm(d[sel], axis=1).mean()
    assert longer > pull + 0.02 * np.linalg.norm(d[sel], axis=1).mean()


def test_the_fits_gradient_and_written_fields_are_its_linear_models(synth_model) -> None:  # type: ignore[no-untyped-def]
    """The objective's gradient matches finite differences, and the strain written to the rig,
    compiled, adds to each channel's field the force the fit's linear model used."""
    from sim.face.scan.strain_fit import StrainCalibration

    cal = StrainCalibration(synth_model)
    rng = np.random.default_rng(5)
    chans = [c for c in cal.force_of][:3]
    vals = np.zeros((2, len(synth_model.channels)))
    for k, c in enumerate(chans):
        vals[k % 2, synth_model.channel_index[c]] = 0.5 + 0.5 * k
    b = 1e-2 * rng.standard_normal((3 * cal.n, 2))
    w = np.array([1.0, 2.0])
    p = 0.1 * rng.standard_normal(cal.n_params)
    _, grad = cal.objective(p, vals, b, w)
    for i in rng.choice(np.flatnonzero(grad), 12, replace=False):
        h = np.zeros_like(p)
        h[i] = 1e-6
        numeric = (cal.objective(p + h, vals, b, w)[0] - cal.objective(p - h, vals, b, w)[0]) / 2e-6
        assert abs(numeric - grad[i]) < 1e-4 * np.abs(grad).max()
    cal.params = np.round(p.clip(-0.4, 0.4), 6)
    written = compile_model(replace(synth_model.rig, strain=cal.strain()), synth_model.params)
    for c in chans:
        i = synth_model.channel_index[c]
        added = written.muscle_matrix[:, i].toarray().ravel() - synth_model.muscle_matrix[:, i].toarray().ravel()
        want = cal.force_of[c] @ cal.params
        assert np.linalg.norm(added - want) < 1e-6 * np.linalg.norm(want)
