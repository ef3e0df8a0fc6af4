"""How long `puppet import-face` takes on a 5k-vertex head (budget: 10 s).

The head is `sim.face.transfer.synthetic`'s full head (wraps all the way round, open at crown and
neck, eye and mouth holes) at 5,200 vertices, written in millimetres and turned on its side so the
orientation and scale estimation run as for a user's file. Measured: reading the OBJ and landmark
JSON, the transfer from the built-in face (resolution 1), compile_model and save_rig — i.e. the
command without its preview picture — then the whole command in a fresh process (imports and the
picture included), once each after one warm-up. Usage: .venv/bin/python benchmarks/import_face.py
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

BUDGET_S = 10.0


def write_head(folder: Path) -> tuple[Path, Path, int]:
    import trimesh
    from scipy.spatial.transform import Rotation

    from sim.face.transfer.synthetic import synthetic_landmarks, synthetic_mesh

    v, t, param = synthetic_mesh(100, 52, full_head=True)
    rot = Rotation.from_euler("zx", [90, 20], degrees=True).as_matrix()
    trimesh.Trimesh(10.0 * v @ rot.T, t, process=False).export(folder / "head.obj")
    (folder / "landmarks.json").write_text(json.dumps(synthetic_landmarks(t, param)))
    return folder / "head.obj", folder / "landmarks.json", len(v)


def import_once(mesh: Path, landmarks: Path, out: Path) -> float:
    from sim.build import compile_model
    from sim.face import default_rig
    from sim.rig import save_rig
    from sim.face.transfer import read_landmarks, read_mesh, transfer_rig

    start = time.perf_counter()
    result = transfer_rig(default_rig(1), read_mesh(mesh), read_landmarks(landmarks))
    compile_model(result.rig)
    save_rig(result.rig, out)
    return time.perf_counter() - start


def main() -> int:
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        mesh, landmarks, n = write_head(folder)
        import_once(mesh, landmarks, folder / "warm.npz")
        seconds = import_once(mesh, landmarks, folder / "head.npz")
        print(f"import of a {n}-vertex head (read, transfer, compile, save): {seconds:.2f} s "
              f"= {seconds / BUDGET_S:.2f} of the {BUDGET_S:.0f} s budget")
        start = time.perf_counter()
        run = subprocess.run([sys.executable, "-m", "puppet", "import-face", str(mesh), "--landmarks",
                              str(landmarks), "--out", str(folder / "cli.npz")], capture_output=True, text=True)
        whole = time.perf_counter() - start
        if run.returncode:
            print(run.stderr.strip())
            return 1
        print(f"whole command in a new process (imports, picture, report): {whole:.2f} s "
              f"= {whole / BUDGET_S:.2f} of the budget")
        return 0 if seconds <= BUDGET_S else 1


if __name__ == "__main__":
    sys.exit(main())
