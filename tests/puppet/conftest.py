"""Rigs that takes recorded on an earlier scanned head replay on bit for bit (as `puppet replay --rig`)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

#: the zygomaticus major's anchor fields (`FaceRig.anchor`) before they were refitted over zones grown
#: 3 cm (docs/scan-face.md, "The smile's cheek"): the takes that drive the smile were recorded on them
ZYGOMATICUS_BEFORE = Path(__file__).parent / "data" / "zygomaticus_fields_before_grown.npz"


@pytest.fixture(scope="session")
def rig_before_grown_smile(tmp_path_factory: pytest.TempPathFactory) -> str:
    """The shipped scanned head's rig with the zygomaticus' fields as they were before the refit: the
    rig the earlier takes replay on (they leave the other refitted channels at 0)."""
    from sim.face.scan.rig import RIG_FILE
    from sim.rig import load_rig, save_rig

    rig = load_rig(RIG_FILE)
    with np.load(ZYGOMATICUS_BEFORE) as before:
        anchor = {**rig.anchor, **{k: np.asarray(before[k]) for k in before.files}}
    path = tmp_path_factory.mktemp("rig") / "ict_before_grown_smile.npz"
    save_rig(replace(rig, anchor=anchor), path)
    return str(path)
