"""The physics never imports the faces built on it: `sim.face` depends on `sim`, not the reverse."""

from __future__ import annotations

import ast
from pathlib import Path

SIM = Path(__file__).resolve().parents[2] / "sim"


def _imported(path: Path) -> set[str]:
    names: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module:
            names.add(node.module)
            names.update(f"{node.module}.{a.name}" for a in node.names)
    return names


def test_physics_modules_do_not_import_the_face_package() -> None:
    physics = [p for p in SIM.rglob("*.py") if SIM / "face" not in p.parents]
    assert len(physics) > 20
    offenders = {p.relative_to(SIM).as_posix(): sorted(n for n in _imported(p) if n == "sim.face" or n.startswith("sim.face."))
                 for p in physics}
    assert {k: v for k, v in offenders.items() if v} == {}


def test_face_package_holds_the_builders() -> None:
    face = {p.name for p in (SIM / "face").glob("*.py")}
    assert {"builder.py", "head.py", "placement.py", "regions.py"} <= face
    assert not list(SIM.glob("face_*.py")) and not (SIM / "muscle_placement.py").exists()
