"""The rig file: round trip, identity hash, and one-line errors for malformed files."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from sim.build import compile_model
from sim.model import FaceRig
from sim.rig import RigFileError, load_rig, save_rig


def test_round_trip_keeps_mesh_muscles_and_hash(synth_rig: FaceRig, tmp_path: Path) -> None:
    path = tmp_path / "face.npz"
    save_rig(synth_rig, path)
    back = load_rig(path)
    a, b = synth_rig.mesh, back.mesh
    for field in ("vertices", "triangles", "held", "jaw_weight", "jaw_pivot", "jaw_axis", "eye_centers",
                  "mouth_loop", "uv"):
        assert np.array_equal(getattr(a, field), getattr(b, field)), field
    assert a.landmarks == b.landmarks and set(a.regions) == set(b.regions)
    assert all(np.array_equal(x, y) for x, y in zip(a.eye_loops, b.eye_loops))
    assert set(back.muscles) == set(synth_rig.muscles)
    for name, parts in synth_rig.muscles.items():
        for m0, m1 in zip(parts, back.muscles[name]):
            assert type(m0) is type(m1)
            for k, v in vars(m0).items():
                assert np.array_equal(np.asarray(v), np.asarray(getattr(m1, k))), (name, k)
    assert compile_model(back).hash == compile_model(synth_rig).hash


def test_hash_changes_with_a_muscle(synth_rig: FaceRig) -> None:
    import dataclasses

    muscles = dict(synth_rig.muscles)
    zyg = muscles["zygomaticus_major_l"][0]
    muscles["zygomaticus_major_l"] = (dataclasses.replace(zyg, scale=zyg.scale * 1.01),)
    other = FaceRig(synth_rig.mesh, muscles, name=synth_rig.name)
    assert compile_model(other).hash != compile_model(synth_rig).hash


def test_a_protruding_ring_round_trips_and_changes_the_hash(synth_rig: FaceRig, tmp_path: Path) -> None:
    """A sphincter's protrusion (the scanned head's pucker) is written only where it is not 0: rig
    files and hashes of faces without it stay as they were, and it reads back as written."""
    import dataclasses

    from sim.model import SphincterMuscle

    path = tmp_path / "face.npz"
    save_rig(synth_rig, path)
    assert not any("protrude" in m for m in _header(path)["muscles"])
    ch, ring = next((ch, m) for ch, parts in synth_rig.muscles.items() for m in parts if isinstance(m, SphincterMuscle))
    muscles = dict(synth_rig.muscles)
    muscles[ch] = tuple(dataclasses.replace(m, protrude=2.5) if m is ring else m for m in muscles[ch])
    pushed = dataclasses.replace(synth_rig, muscles=muscles)
    save_rig(pushed, path)
    back = load_rig(path)
    assert [m.protrude for m in back.muscles[ch] if isinstance(m, SphincterMuscle)] == [2.5]
    assert compile_model(back).hash == compile_model(pushed).hash != compile_model(synth_rig).hash


def _rewrite(src: Path, dst: Path, **changes: object) -> None:
    with np.load(src, allow_pickle=False) as d:
        arrays = {k: d[k] for k in d.files}
    for k, v in changes.items():
        if v is None:
            arrays.pop(k)
        else:
            arrays[k] = v  # type: ignore[assignment]
    with open(dst, "wb") as fh:
        np.savez(fh, **arrays)


def _header(src: Path) -> dict:
    with np.load(src, allow_pickle=False) as d:
        return json.loads(str(d["header"]))


@pytest.mark.parametrize("case", ["garbage", "missing", "no_header", "version", "tri_range", "muscle_field",
                                  "pickled", "nan", "landmark", "pinched_loop"])
def test_malformed_rig_raises_one_line_naming_the_file(synth_rig: FaceRig, tmp_path: Path, case: str) -> None:
    good = tmp_path / "good.npz"
    save_rig(synth_rig, good)
    bad = tmp_path / f"{case}.npz"
    head = _header(good)
    if case == "garbage":
        bad.write_bytes(b"PK\x03\x04 this is not a zip")
    elif case == "missing":
        bad = tmp_path / "nowhere.npz"
    elif case == "no_header":
        _rewrite(good, bad, header=None)
    elif case == "version":
        head["version"] = 99
        _rewrite(good, bad, header=np.array(json.dumps(head)))
    elif case == "tri_range":
        with np.load(good) as d:
            tris = d["triangles"].copy()
        tris[0, 0] = 10**6
        _rewrite(good, bad, triangles=tris)
    elif case == "muscle_field":
        del head["muscles"][0]["scale"]
        _rewrite(good, bad, header=np.array(json.dumps(head)))
    elif case == "pickled":
        _rewrite(good, bad, vertices=np.array([{"evil": 1}], dtype=object))
    elif case == "nan":
        with np.load(good) as d:
            v = d["vertices"].copy()
        v[3, 1] = np.nan
        _rewrite(good, bad, vertices=v)
    elif case == "landmark":
        head["landmarks"]["chin"] = -5
        _rewrite(good, bad, header=np.array(json.dumps(head)))
    elif case == "pinched_loop":  # an opening's border through one vertex twice (an older import)
        with np.load(good) as d:
            loop = d["mouth_loop"].copy()
        _rewrite(good, bad, mouth_loop=np.concatenate([loop, loop[2:3]]))
    with pytest.raises(RigFileError) as info:
        load_rig(bad)
    msg = str(info.value)
    assert isinstance(info.value, ValueError)
    assert str(bad) in msg and "\n" not in msg


def test_default_rig_with_wrinkles_round_trips(tmp_path: Path) -> None:
    from sim.face import default_rig

    rig = default_rig(0)
    assert rig.wrinkles  # the wrinkle mask is part of the default rig
    path = tmp_path / "default.npz"
    save_rig(rig, path)
    back = load_rig(path)
    assert [w.name for w in back.wrinkles] == [w.name for w in rig.wrinkles]
    assert compile_model(back).hash == compile_model(rig).hash


def test_a_text_file_given_as_rig_is_one_clear_line(tmp_path) -> None:
    from sim.rig import RigFileError, load_rig

    bad = tmp_path / "notes.npz"
    bad.write_text("not a rig\n")
    with pytest.raises(RigFileError, match="not a rig file") as info:
        load_rig(bad)
    assert "pickle" not in str(info.value)


def test_insertion_gains_round_trip_and_shape_the_field(synth_rig: FaceRig, tmp_path: Path) -> None:
    """Fitted insertion gains are kept by the rig file and scale the channel's force where they are
    set: gain 2 over the face doubles the channel's nodal force, gain 0 takes it away."""
    from dataclasses import replace

    import numpy as np

    ch = next(iter(synth_rig.muscles))
    n = len(synth_rig.mesh.vertices)
    gain = np.where(np.arange(n) % 2 == 0, 2.0, 0.0)
    rig = replace(synth_rig, insertion={ch: gain})
    save_rig(rig, tmp_path / "g.npz")
    back = load_rig(tmp_path / "g.npz")
    assert np.array_equal(back.insertion[ch], gain)
    plain, fitted = compile_model(synth_rig), compile_model(back)
    assert fitted.hash != plain.hash
    j = plain.channel_index[ch]
    f0 = plain.muscle_matrix[:, j].toarray().reshape(n, 3)
    f1 = fitted.muscle_matrix[:, j].toarray().reshape(n, 3)
    assert np.abs(f0).max() > 0
    assert np.allclose(f1[::2], 2 * f0[::2]) and not np.any(f1[1::2])



def test_the_integrator_a_face_asks_for_round_trips_and_runs(synth_rig: FaceRig, tmp_path: Path) -> None:
    """An imported head asks for the implicit integrator (its fold guard); the rig file keeps the
    request, the simulator honours it, and a rig that names an unknown one is one clear line."""
    from dataclasses import replace

    from sim.integrator import Simulator

    path = tmp_path / "r.npz"
    save_rig(replace(synth_rig, integrator="implicit"), path)
    back = load_rig(path)
    assert back.integrator == "implicit"
    assert Simulator(compile_model(back), wrinkles=False).method == "implicit"
    assert compile_model(back).hash != compile_model(synth_rig).hash  # a replay knows which it ran on
    save_rig(synth_rig, path)
    assert load_rig(path).integrator == "auto"
    data = dict(np.load(path))
    header = json.loads(str(data["header"]))
    header["integrator"] = "euler"
    data["header"] = np.array(json.dumps(header))
    np.savez(tmp_path / "bad.npz", **data)
    with pytest.raises(RigFileError, match=r"bad\.npz: integrator must be one of auto, rk2, implicit") as err:
        load_rig(tmp_path / "bad.npz")
    assert "\n" not in str(err.value)


def test_the_presets_a_face_asks_for_round_trip(synth_rig: FaceRig, tmp_path: Path) -> None:
    """An imported head takes the presets of a face without teeth; the rig file keeps that, a rig
    that asks for none keeps its file unchanged and takes the presets by its name."""
    from dataclasses import replace

    from sim.facs import EXPRESSIONS, expressions_for, preset_face

    path = tmp_path / "r.npz"
    save_rig(replace(synth_rig, presets="imported"), path)
    back = load_rig(path)
    assert back.presets == "imported" and preset_face(back) == "imported"
    assert expressions_for(preset_face(back))["fear"] != EXPRESSIONS["fear"]
    save_rig(synth_rig, path)
    header = json.loads(str(np.load(path)["header"]))
    assert "presets" not in header
    assert preset_face(load_rig(path)) == synth_rig.name


def test_skin_material_round_trips_and_sets_the_skin(synth_rig: FaceRig, tmp_path: Path) -> None:
    """Fitted skin multipliers are kept by the rig file and set the compiled skin where they are:
    the tether and the normal support per vertex, a spring by the mean of its two ends'; a field
    not named stays uniform, and a face without any keeps its hash."""
    from dataclasses import replace

    n = len(synth_rig.mesh.vertices)
    lax = np.where(np.arange(n) % 2 == 0, 0.25, 1.0)
    rig = replace(synth_rig, skin={"tether": lax, "modulus": 2.0 * lax})
    save_rig(rig, tmp_path / "s.npz")
    back = load_rig(tmp_path / "s.npz")
    assert set(back.skin) == {"tether", "modulus"} and np.array_equal(back.skin["tether"], lax)
    plain, fitted = compile_model(synth_rig), compile_model(back)
    assert fitted.hash != plain.hash
    assert compile_model(replace(synth_rig, skin={})).hash == plain.hash
    assert np.allclose(fitted.rest_stiffness, plain.rest_stiffness * lax)
    assert np.array_equal(fitted.support_stiffness, plain.support_stiffness)
    i, j = np.asarray(plain.spring_indices).T
    assert np.allclose(fitted.spring_k_low, plain.spring_k_low * (lax[i] + lax[j]))


def test_a_rig_with_an_unknown_skin_field_is_one_clear_line(synth_rig: FaceRig, tmp_path: Path) -> None:
    from dataclasses import replace

    n = len(synth_rig.mesh.vertices)
    save_rig(replace(synth_rig, skin={"tether": np.ones(n)}), tmp_path / "s.npz")
    data = dict(np.load(tmp_path / "s.npz"))
    header = json.loads(str(data["header"]))
    header["skin"] = ["stickiness"]
    data["header"] = np.array(json.dumps(header))
    data["skin_stickiness"] = np.ones(n)
    np.savez(tmp_path / "bad.npz", **data)
    with pytest.raises(RigFileError, match=r"bad\.npz: skin field must be one of") as err:
        load_rig(tmp_path / "bad.npz")
    assert "\n" not in str(err.value)
    data["header"] = np.array(json.dumps({**header, "skin": ["tether"]}))
    data["skin_tether"] = -np.ones(n)
    np.savez(tmp_path / "neg.npz", **data)
    with pytest.raises(RigFileError, match=r"neg\.npz: skin multipliers of .tether. must lie in 0\.\.1000"):
        load_rig(tmp_path / "neg.npz")


def test_named_tissue_round_trips_on_top_of_the_skin(synth_rig: FaceRig, tmp_path: Path) -> None:
    """A named structure of the skin (a retaining ligament's tether, the lid fold's laxity) is kept
    by the rig file and multiplies its skin field on top of the fitted one; a face without any
    keeps its hash."""
    from dataclasses import replace

    n = len(synth_rig.mesh.vertices)
    held = np.where(np.arange(n) % 3 == 0, 10.0, 1.0)
    lax = np.where(np.arange(n) % 2 == 0, 0.5, 1.0)
    rig = replace(synth_rig, skin={"tether": lax}, tissue={"tether_ligament": held, "modulus_fold": lax})
    save_rig(rig, tmp_path / "t.npz")
    back = load_rig(tmp_path / "t.npz")
    assert set(back.tissue) == {"tether_ligament", "modulus_fold"}
    assert np.array_equal(back.tissue["tether_ligament"], held)
    plain, skinned, both = compile_model(synth_rig), compile_model(replace(rig, tissue={})), compile_model(back)
    assert len({plain.hash, skinned.hash, both.hash}) == 3
    assert compile_model(replace(synth_rig, tissue={})).hash == plain.hash
    assert np.allclose(both.rest_stiffness, plain.rest_stiffness * lax * held)
    i, j = np.asarray(plain.spring_indices).T
    assert np.allclose(both.spring_k_low, plain.spring_k_low * 0.5 * (lax[i] + lax[j]))


def test_a_tissue_structure_not_named_after_a_skin_field_is_one_clear_line(synth_rig: FaceRig,
                                                                           tmp_path: Path) -> None:
    from dataclasses import replace

    n = len(synth_rig.mesh.vertices)
    save_rig(replace(synth_rig, tissue={"tether_ligament": np.ones(n)}), tmp_path / "t.npz")
    data = dict(np.load(tmp_path / "t.npz"))
    header = json.loads(str(data["header"]))
    data["header"] = np.array(json.dumps({**header, "tissue": ["glue_ligament"]}))
    data["tissue_glue_ligament"] = np.ones(n)
    np.savez(tmp_path / "bad.npz", **data)
    with pytest.raises(RigFileError, match=r"bad\.npz: a tissue structure is named") as err:
        load_rig(tmp_path / "bad.npz")
    assert "\n" not in str(err.value)
    data["header"] = np.array(json.dumps(header))
    data["tissue_tether_ligament"] = -np.ones(n)
    np.savez(tmp_path / "neg.npz", **data)
    with pytest.raises(RigFileError, match=r"neg\.npz: tissue multipliers of .tether_ligament. must lie"):
        load_rig(tmp_path / "neg.npz")


def test_the_tissue_carried_by_the_eyes_round_trips(synth_rig: FaceRig, tmp_path: Path) -> None:
    """The look fields (`FaceRig.gaze`) are kept by the rig file and change the face's hash; a face
    without them keeps its hash; a field named for no look, or out of range, is one clear line."""
    from dataclasses import replace

    n = len(synth_rig.mesh.vertices)
    field = np.where(np.arange(n)[:, None] % 4 == 0, 0.1, 0.0) * np.array([1.0, -0.5, 0.2])
    rig = replace(synth_rig, gaze={"in_l": field, "down_r": -field})
    save_rig(rig, tmp_path / "g.npz")
    back = load_rig(tmp_path / "g.npz")
    assert set(back.gaze) == {"in_l", "down_r"} and np.array_equal(back.gaze["down_r"], -field)
    assert compile_model(back).hash != compile_model(synth_rig).hash
    assert compile_model(replace(synth_rig, gaze={})).hash == compile_model(synth_rig).hash
    data = dict(np.load(tmp_path / "g.npz"))
    header = json.loads(str(data["header"]))
    data["header"] = np.array(json.dumps({**header, "gaze": ["sideways_l"]}))
    data["gaze_sideways_l"] = field
    np.savez(tmp_path / "bad.npz", **data)
    with pytest.raises(RigFileError, match=r"bad\.npz: a gaze field is one of") as err:
        load_rig(tmp_path / "bad.npz")
    assert "\n" not in str(err.value)
    data["header"] = np.array(json.dumps(header))
    data["gaze_in_l"] = 3.0 + field
    np.savez(tmp_path / "far.npz", **data)
    with pytest.raises(RigFileError, match=r"far\.npz: anchor displacements of the gaze's .in_l. must lie"):
        load_rig(tmp_path / "far.npz")
