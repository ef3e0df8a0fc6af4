"""The default face and its steps give the same bits whichever BLAS kernel the process loads.

OpenBLAS picks its kernel per CPU, or from OPENBLAS_CORETYPE, and the last bits of `a @ b` follow it.
A take recorded in one process and replayed in another (a test harness with a trimmed environment,
a systemd unit, another shell) must still verify bit for bit, so building and stepping the live
default face may not go through BLAS (sim.rowmath). Two kernels with different arithmetic (AVX with
no FMA, and AVX2 with FMA) are forced in two fresh processes that build the face uncached and step
it through an expression with the jaw open; the model hash and the final state must agree."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

PROBE = """
import hashlib
from sim.face import targets as et
from sim.face import default_model
from sim.integrator import Simulator
m = default_model(0)
sim = Simulator(m, wrinkles=False)
state = m.rest_state()
for pose in ("AU27", "AU6+12"):
    control = et.pose_control(pose)
    for _ in range(20):
        sim.step(state, control)
print(m.hash, hashlib.sha256(state.positions.tobytes() + state.velocities.tobytes()).hexdigest())
"""


def _run(coretype: str) -> str:
    env = {k: v for k, v in os.environ.items() if not k.startswith("OPENBLAS")}
    env.update(OPENBLAS_CORETYPE=coretype, PUPPET_CACHE_DIR="off", PYTHONPATH=str(ROOT))
    out = subprocess.run([sys.executable, "-c", PROBE], env=env, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    return out.stdout.strip()


def test_the_default_face_does_not_depend_on_the_blas_kernel() -> None:
    assert _run("Sandybridge") == _run("Haswell")
