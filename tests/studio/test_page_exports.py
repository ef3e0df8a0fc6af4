"""The page's exports (puppet/panel/takes.py) under a user clicking again and again or a script
posting many: one export runs at a time, a few wait their turn, the rest are answered busy; an
export never replaces a file beside the take."""

from __future__ import annotations

import http.client
import json
import sys
import time
from pathlib import Path

import pytest

from puppet.cli import main
from puppet.library.store import Library
from puppet.panel.server import PanelServer
from puppet.panel.takes import MAX_WAITING, TakeRoutes
from takes import write_take

# an export that waits for the test's gate, then notes its start and end in a log (the order shows
# whether two ran at once) and writes its output
FAKE_EXPORT = """
import os, sys, time
gate, log, out = sys.argv[1:4]
end = time.monotonic() + 600  # a test that failed before opening the gate leaves no process behind
while not os.path.exists(gate):
    if time.monotonic() > end:
        sys.exit(1)
    time.sleep(0.02)
with open(log, "a") as fh:
    fh.write("start " + os.path.basename(out) + "\\n")
with open(out, "w") as fh:
    fh.write("exported\\n")
with open(log, "a") as fh:
    fh.write("end " + os.path.basename(out) + "\\n")
"""


def request(port: int, method: str, path: str) -> tuple[int, dict]:
    c = http.client.HTTPConnection("127.0.0.1", port, timeout=60)
    try:
        c.request(method, path)
        r = c.getresponse()
        return r.status, json.loads(r.read())
    finally:
        c.close()


def wait_ended(port: int, n: int) -> list[dict]:
    end = time.monotonic() + 120
    while time.monotonic() < end:
        jobs = request(port, "GET", "/api/takes/exports")[1]["exports"]
        if len(jobs) >= n and all(j["state"] in ("done", "failed") for j in jobs):
            return jobs
        time.sleep(0.1)
    raise AssertionError(f"the exports did not end: {jobs}")


@pytest.fixture
def page(tmp_path: Path):
    """Three takes in a library and the page's take routes served alone; yields (port, routes, takes)."""
    lib = tmp_path / "takes.db"
    takes = [write_take(tmp_path / "shoot" / f"{n}.jsonl", ticks=20, seed=i) for i, n in enumerate("abc")]
    with Library(lib) as library:
        for t in takes:
            library.register(t)
    routes = TakeRoutes(lambda: lib)
    srv = PanelServer("127.0.0.1", 0, "panel.html", routes.add)
    srv.start()
    yield srv.port, routes, takes
    srv.stop()


def gated(routes: TakeRoutes, tmp_path: Path) -> tuple[Path, Path]:
    gate, log = tmp_path / "gate", tmp_path / "log"
    script = tmp_path / "fake_export.py"
    script.write_text(FAKE_EXPORT)
    routes.argv = lambda take, out: [sys.executable, str(script), str(gate), str(log), str(out)]  # type: ignore[method-assign]
    return gate, log


def test_exports_run_one_at_a_time_and_a_flood_is_answered_busy(page, tmp_path: Path) -> None:
    """Before, every click started `puppet replay --out` at once: a script posting dozens started
    dozens of render processes."""
    port, routes, takes = page
    gate, log = gated(routes, tmp_path)
    asks = [(i, kind) for i in (1, 2, 3) for kind in ("mp4", "pc2", "csv")]
    answers = [request(port, "POST", f"/api/takes/{i}/export?to={kind}") for i, kind in asks]
    taken = [a for a in answers if a[1]["ok"]]
    busy = [a for a in answers if not a[1]["ok"]]
    assert len(taken) == 1 + MAX_WAITING and [a[0] for a in taken] == [200] * len(taken), answers
    assert busy and all(s == 429 and a.get("busy") and "try again" in a["error"] for s, a in busy), answers
    assert [a[1]["state"] for a in taken] == ["running"] + ["waiting"] * MAX_WAITING
    assert [a[1]["ahead"] for a in taken] == list(range(len(taken)))
    # the same button again: the export under way, not a second one
    again = request(port, "POST", "/api/takes/1/export?to=pc2")
    assert again[1]["ok"] and again[1]["out"] == taken[1][1]["out"]
    gate.touch()
    jobs = wait_ended(port, len(taken))
    assert [j["state"] for j in jobs] == ["done"] * len(taken)
    lines = log.read_text().split()[::2]
    assert lines == ["start", "end"] * len(taken), log.read_text()  # never two at once
    for _, a in taken:
        assert Path(a["out"]).read_text() == "exported\n"
    # the queue has room again
    assert request(port, "POST", "/api/takes/3/export?to=csv")[1]["ok"]
    wait_ended(port, len(taken) + 1)


def test_an_export_never_replaces_a_file(page, tmp_path: Path) -> None:
    """Before, an export from the page replaced `STEM.csv` beside the take without asking."""
    port, _, takes = page
    mine = takes[0].with_suffix(".csv")
    mine.write_text("my own notes\n")
    status, a = request(port, "POST", "/api/takes/1/export?to=csv")
    assert status == 200 and a["ok"] and Path(a["out"]).name == "a-2.csv", a
    jobs = wait_ended(port, 1)
    assert jobs[-1]["state"] == "done", jobs
    assert mine.read_text() == "my own notes\n"
    assert main(["replay", str(takes[0]), "--out", str(tmp_path / "single.csv")]) == 0
    assert Path(a["out"]).read_bytes() == (tmp_path / "single.csv").read_bytes()


def test_a_name_taken_while_the_export_waited_is_kept(page, tmp_path: Path) -> None:
    port, routes, takes = page
    gate, _ = gated(routes, tmp_path)
    request(port, "POST", "/api/takes/1/export?to=mp4")  # runs, held at the gate
    b = request(port, "POST", "/api/takes/2/export?to=csv")[1]
    assert b["state"] == "waiting" and Path(b["out"]).name == "b.csv"
    takes[1].with_suffix(".csv").write_text("written meanwhile\n")
    gate.touch()
    jobs = wait_ended(port, 2)
    assert takes[1].with_suffix(".csv").read_text() == "written meanwhile\n"
    assert Path(jobs[-1]["out"]).name == "b-2.csv" and Path(jobs[-1]["out"]).read_text() == "exported\n"


def test_unused_output_counts_what_an_export_writes(tmp_path: Path) -> None:
    from puppet.export.runner import unused_output

    (tmp_path / "t.obj").write_text("a mesh of the user's\n")  # a PC2 writes its rest mesh beside it
    assert unused_output(tmp_path / "t.pc2").name == "t-2.pc2"
    (tmp_path / "t.arkit.csv").write_text("x")
    assert unused_output(tmp_path / "t.arkit.csv").name == "t-2.arkit.csv"
    assert unused_output(tmp_path / "t.mp4", [tmp_path / "t.mp4", tmp_path / "t-2.mp4"]).name == "t-3.mp4"
    assert unused_output(tmp_path / "u.csv") == tmp_path / "u.csv"
