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
