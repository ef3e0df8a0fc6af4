"""The editor's export (`puppet edit`'s /api/export) under a user pressing it again and again: one
export at a time, another answered busy at once; an export never replaces a file beside the take."""

from __future__ import annotations

import http.client
import json
import subprocess
import sys
import threading
from pathlib import Path

import pytest
from panel_browser import CHILD_ENV, ROOT

SCRIPT = ROOT / "examples" / "mock" / "sgi_rehearsal.toml"


@pytest.fixture(scope="module")
def editor(tmp_path_factory: pytest.TempPathFactory):
    from puppet.panel.editor import Editor
    from puppet.panel.server import PanelServer

    d = tmp_path_factory.mktemp("exports")
    subprocess.run([sys.executable, "-m", "puppet", "live", "--device", f"mock://{SCRIPT}?speed=0", "--headless",
                    "--duration", "1", "--record", "take.jsonl"], cwd=d, check=True, capture_output=True,
                   env=CHILD_ENV)
    ed = Editor(d / "take.jsonl")
    srv = PanelServer("127.0.0.1", 0, "editor.html", ed.routes)
    srv.start()
    yield srv.port, d, ed
    srv.stop()
    ed.close()


def export(port: int, name: str) -> tuple[int, dict]:
    c = http.client.HTTPConnection("127.0.0.1", port, timeout=120)
    try:
        c.request("POST", "/api/export", body=json.dumps({"name": name}), headers={"Content-Type": "application/json"})
        r = c.getresponse()
        return r.status, json.loads(r.read())
    finally:
        c.close()


def test_an_export_never_replaces_a_file(editor) -> None:
    """Before, exporting to a name that existed replaced that file without asking."""
    port, d, _ = editor
    mine = d / "take-edit.csv"
    mine.write_text("my own notes\n")
    status, got = export(port, "take-edit.csv")
    assert status == 200 and got["ok"] and mine.read_text() == "my own notes\n", got
    assert got["out"] == "take-edit-2.csv" and "take-edit-2.csv" in got["message"]
    assert (d / "take-edit-2.csv").read_text().startswith("frame,")
    assert export(port, "take-edit.csv")[1]["out"] == "take-edit-3.csv"


def test_a_second_export_while_one_runs_is_answered_busy(editor) -> None:
    """Before, every press queued another export behind the running one: a script's requests piled
    up as exports for minutes."""
    port, d, ed = editor
    gate = threading.Event()
    ed.work_pool.submit(gate.wait, 60)  # the export thread busy until the gate opens
    first: list = []
    t = threading.Thread(target=lambda: first.append(export(port, "held.csv")))
    t.start()
    try:
        for _ in range(600):
            if ed.exporting is not None:
                break
            t.join(0.05)
        assert ed.exporting is not None and ed.exporting.name == "held.csv"
        status, got = export(port, "other.csv")
        assert status == 429 and got.get("busy") and "held.csv" in got["error"], got
        assert not (d / "other.csv").exists()
    finally:
        gate.set()
        t.join(120)
    assert first and first[0][0] == 200 and first[0][1]["out"] == "held.csv"
    assert export(port, "other.csv")[1]["ok"]  # the editor exports again once it is done
