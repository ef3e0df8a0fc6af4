"""The page's edit button on a take the editor cannot open: the page shows the editor's own one
line (the take's path and what to do), not a bare "did not start"."""

from __future__ import annotations

import http.client
import json
from pathlib import Path

from puppet.library.store import Library
from puppet.panel.server import PanelServer
from puppet.panel.takes import TakeRoutes
from takes import write_take


def test_edit_of_a_take_with_no_tick_says_why(tmp_path: Path) -> None:
    full = write_take(tmp_path / "full.jsonl", ticks=5)
    take = tmp_path / "stopped.jsonl"
    take.write_text(full.read_text().splitlines()[0] + "\n")  # the header only: stopped before a tick
    lib = tmp_path / "takes.db"
    with Library(lib, warn=lambda s: None) as library:
        take_id = library.register(take)
    routes = TakeRoutes(lambda: lib)
    srv = PanelServer("127.0.0.1", 0, "panel.html", routes.add)
    srv.start()
    try:
        c = http.client.HTTPConnection("127.0.0.1", srv.port, timeout=120)
        c.request("POST", f"/api/takes/{take_id}/edit")
        got = json.loads(c.getresponse().read())
        c.close()
    finally:
        srv.stop()
    assert not got["ok"], got
    error = got["error"]
    assert str(take) in error and "nothing to edit" in error and "record it again" in error, error
    assert "\n" not in error and "Traceback" not in error


def test_edit_pressed_again_opens_the_same_editor_and_a_flood_is_busy(tmp_path: Path,
                                                                      monkeypatch) -> None:
    """Each press of a take's edit button started another `puppet edit` process (each holding a
    face and a port), however many: pressing again answers the take's editor, and past
    MAX_EDITORS takes the page answers busy."""
    import subprocess
    import sys

    from puppet.panel import device
    from puppet.panel.takes import MAX_EDITORS

    started: list[subprocess.Popen] = []

    def fake_editor(take: str):  # an editor process that serves until it is ended
        proc = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(600)"])
        started.append(proc)
        return proc, f"http://127.0.0.1:1/{len(started)}"

    monkeypatch.setattr(device, "_start_editor", fake_editor)
    lib = tmp_path / "takes.db"
    takes = [write_take(tmp_path / f"t{i}.jsonl", ticks=5, seed=i) for i in range(MAX_EDITORS + 1)]
    with Library(lib, warn=lambda s: None) as library:
        ids = [library.register(t) for t in takes]
    srv = PanelServer("127.0.0.1", 0, "panel.html", TakeRoutes(lambda: lib).add)
    srv.start()

    def edit(take_id: int) -> tuple[int, dict]:
        c = http.client.HTTPConnection("127.0.0.1", srv.port, timeout=60)
        c.request("POST", f"/api/takes/{take_id}/edit")
        r = c.getresponse()
        got = (r.status, json.loads(r.read()))
        c.close()
        return got

    try:
        first = edit(ids[0])
        assert first[1]["ok"] and edit(ids[0]) == first and len(started) == 1
        for i in ids[1:MAX_EDITORS]:
            assert edit(i)[1]["ok"]
        status, got = edit(ids[MAX_EDITORS])
        assert status == 429 and got["busy"] and "editors are open" in got["error"], got
        assert len(started) == MAX_EDITORS
        started[1].kill()
        started[1].wait()
        assert edit(ids[MAX_EDITORS])[1]["ok"]  # an editor that ended makes room
    finally:
        srv.stop()
        for p in started:
            p.kill()
            p.wait()
    assert all(p.poll() is not None for p in started)
