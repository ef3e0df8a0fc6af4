"""The recognition templates are the presets as the face plays them (its own intensities,
`sim.facs.FACE_EXPRESSIONS`), not the shared table's."""

from __future__ import annotations

import numpy as np
import pytest


@pytest.fixture(scope="module")
def settler():  # type: ignore[no-untyped-def]
    import sim.face
    from sim.fit.basis import Settler

    return Settler(sim.face.default_model(0), max_seconds=1.0)


def test_templates_take_the_faces_own_preset_intensities(settler, monkeypatch: pytest.MonkeyPatch) -> None:  # type: ignore[no-untyped-def]
    """A face whose happiness is a half smile with no cheek raise: its template's activations are
    that half smile, and its settled field is the half smile's settled pose. Before, the templates
    were settled from the shared table (AU6 0.6 + AU12 1.0) whatever the face played, so on the
    scanned head (surprise with the lids raised, sadness without the outer brows, ...) a take of
    its own presets was scored against poses it never makes."""
    from sim import facs
    from sim.fit.basis import build_templates, preset_values

    face = facs.preset_face(settler.model.rig)
    assert face and face not in facs.FACE_EXPRESSIONS  # the procedural face: the shared table
    own = {"happiness": {"AU12": 0.5}}
    monkeypatch.setitem(facs.FACE_EXPRESSIONS, face, own)
    tpl = build_templates(settler, weights=(1.0,))
    e = tpl.names.index("happiness")
    want = preset_values("happiness", 1.0, face)
    shared = preset_values("happiness", 1.0)
    assert want != shared
    got = {ch: float(v) for ch, v in zip(tpl.channels, tpl.activations[e]) if v != 0}
    assert got == pytest.approx({ch: v for ch, v in want.items() if ch in tpl.channels})
    field = settler.pose(settler.values_for(want)) - settler.rest
    np.testing.assert_allclose(tpl.fields[e, 0], field, atol=1e-9)
    other = settler.pose(settler.values_for(shared)) - settler.rest
    assert np.abs(other - field).max() > 10 * np.abs(tpl.fields[e, 0] - field).max() + 1e-6


def test_the_scanned_heads_presets_differ_from_the_shared_table() -> None:
    """What makes the change matter on the default face: its surprise raises the upper lids."""
    from sim.fit.basis import preset_values

    ict, shared = preset_values("surprise", 1.0, "ict"), preset_values("surprise", 1.0)
    assert set(ict) - set(shared), (ict, shared)
