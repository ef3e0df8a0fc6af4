"""The performer's page end to end: `puppet live --panel PORT` in its own process, real headless
chromium pages dragging sliders and pressing pads; the recording says what the loop applied, and
a replay of it renders the face that moved."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from panel_browser import PuppetProcess, browser, quit_browser, wait_for
from selenium.webdriver.common.action_chains import ActionChains
from selenium.webdriver.common.by import By


@pytest.fixture(scope="module")
def show(tmp_path_factory: pytest.TempPathFactory):
    """One live show for the module: headless, the page on an OS-chosen port, a mouth role."""
    d = tmp_path_factory.mktemp("show")
    proc = PuppetProcess("live", "--headless", "--panel", "0", "--duration", "120", "--record", "take.jsonl",
                         "--panel-role", "mouth=jaw,orbicularis_oris,zygomaticus_major,expr:happiness", cwd=d)
    yield proc, d
    proc.stop()


def drag(drv, channel: str, frac: float) -> None:
    s = drv.find_element(By.CSS_SELECTOR, f'.slider[data-channel="{channel}"]')
    w = s.size["width"]
    ActionChains(drv).move_to_element_with_offset(s, -w // 2 + 2, 0).click_and_hold() \
        .move_by_offset(int(w * frac), 0).release().perform()


def applied(drv, channel: str) -> float | None:
    return drv.execute_script(
        "const p = window.puppetPanel; if (!p.values) return null; return p.values[p.index[arguments[0]]];", channel)


def ticking(drv) -> bool:
    return bool(drv.execute_script("return window.puppetPanel.values !== null"))


def records(path: Path) -> list[dict]:
    return [json.loads(x) for x in path.read_text().splitlines() if x.strip()]


def test_page_drives_the_face_with_two_pages(show) -> None:
    proc, d = show
    url = proc.url
    a, b = browser(), browser()
    try:
        a.get(url + "?name=alice&role=mouth")
        b.get(url + "?name=bob")
        for drv in (a, b):
            wait_for(lambda drv=drv: ticking(drv), 60, "the live loop's values on the page")
        # alice drags the jaw: the loop applies it, and bob's page shows alice's slider live
        drag(a, "jaw", 0.7)
        own = a.execute_script("return window.puppetPanel.own['slider:jaw']")
        assert own > 0.4
        # nothing else drives the jaw: what the loop applies comes to alice's own value
        wait_for(lambda: abs((applied(a, "jaw") or 0) - own) < 1e-3, 10, "the jaw applied")
        wait_for(lambda: b.find_elements(By.CSS_SELECTOR, '.slider[data-channel="jaw"] .other'), 10,
                 "alice's jaw shown on bob's page")
        assert (applied(b, "jaw") or 0) > 0.4
        # alice is limited to the mouth role: the brow sliders are locked on her page and a message
        # forged for them is dropped by the server
        assert "locked" in a.find_element(By.CSS_SELECTOR, '.slider[data-channel="frontalis_inner_l"]').get_attribute("class")
        a.execute_script("window.puppetPanel.ws.send(JSON.stringify({t:'in', c:'slider:frontalis_inner_l', v:1}))")
        # bob presses the happiness pad (a radio preset): the smile rises on both pages
        b.find_element(By.CSS_SELECTOR, 'button[data-control="pad:expr:happiness"]').click()
        wait_for(lambda: (applied(a, "zygomaticus_major_l") or 0) > 0.3, 10, "the happiness preset applied")
        assert (applied(a, "frontalis_inner_l") or 0) == 0.0
        a.find_element(By.ID, "marker").click()
        wait_for(lambda: a.find_elements(By.CSS_SELECTOR, "#markers li"), 10, "the marker listed")
        states = a.find_elements(By.CSS_SELECTOR, "#devices .dev.ok")
        assert len(states) >= 3  # the server and both pages, connected
        a.save_screenshot(str(d / "panel.png"))
        # the editor button opens the take recorded so far in the force-graph editor (a new tab)
        a.find_element(By.ID, "edit").click()
        wait_for(lambda: len(a.window_handles) == 2, 10, "the editor's tab")
        a.switch_to.window(a.window_handles[1])
        wait_for(lambda: "/api" not in a.current_url and a.current_url.startswith("http://127.0.0.1")
                 and a.execute_script("return !!(window.puppetEditor && window.puppetEditor.ready)"), 90, "the editor")
        assert a.execute_script("return window.puppetEditor.take.take") == "take.jsonl"
    finally:
        quit_browser(a)
        quit_browser(b)
    out = proc.stop()
    assert "performer's page at http://127.0.0.1:" in out
    recs = records(d / "take.jsonl")
    evs = [r for r in recs if r["t"] == "ev"]
    devs = {r["dev"] for r in evs}
    assert any(x.endswith("/alice") for x in devs) and any(x.endswith("/bob") for x in devs)
    assert not any(r["ctl"] == "slider:frontalis_inner_l" for r in evs)
    assert any(r["t"] == "mark" for r in recs)
    # the recording replays bit-exactly, and its last frame shows an open mouth against the rest
    from puppet.replay import Replayer, build_performance
    from puppet.session import read_session

    perf = build_performance(read_session(d / "take.jsonl"), None)
    names = [c.name for c in perf.face.vocab.channels]
    assert perf.values[:, names.index("jaw")].max() > 0.4
    rp = Replayer(perf)
    rp.seek(perf.ticks)
    assert perf.checks and not rp.mismatches and rp.verified > 0
    from render.offscreen import OffscreenRenderer

    with OffscreenRenderer(perf.face.model, (320, 240)) as r:
        moved = r.render_frame(rp.state).astype(float)
        rest = r.render_frame(perf.face.model.rest_state()).astype(float)
    assert np.abs(moved - rest).mean() > 0.5


def test_window_with_no_box_gives_keyboard_and_page(xvfb_display: str, tmp_path: Path) -> None:
    import os
    import subprocess
    import sys

    from panel_browser import ROOT

    env = dict(os.environ, PYTHONPATH=str(ROOT), DISPLAY=xvfb_display)
    r = subprocess.run([sys.executable, "-m", "puppet", "live", "--duration", "2", "--record", "w.jsonl"],
                       cwd=tmp_path, env=env, capture_output=True, text=True, timeout=180)
    assert r.returncode == 0, r.stderr
    assert "performer's page at http://127.0.0.1:" in r.stdout
    header = json.loads((tmp_path / "w.jsonl").read_text().splitlines()[0])
    assert "keyboard://" in header["devices"] and any(d.startswith("panel://") for d in header["devices"])
    text = header["mapping"]["text"]
    assert 'control = "key:Q"' in text and 'control = "slider:jaw"' in text  # the whole key map and the page's


def test_panel_port_and_no_panel_contracts(tmp_path: Path) -> None:
    import os
    import socket
    import subprocess
    import sys
    import urllib.request

    from panel_browser import ROOT

    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    proc = PuppetProcess("live", "--headless", "--panel", str(port), "--duration", "60", cwd=tmp_path)
    try:
        assert proc.url == f"http://127.0.0.1:{port}/"
        with urllib.request.urlopen(proc.url, timeout=10) as r:
            assert r.status == 200 and b"performer" in r.read()
    finally:
        proc.stop()
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    env.pop("DISPLAY", None)
    script = ROOT / "examples" / "mock" / "sgi_rehearsal.toml"  # real time: a page would be served
    r = subprocess.run([sys.executable, "-m", "puppet", "live", "--headless", "--no-panel", "--device", f"mock://{script}",
                        "--duration", "1"], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0 and "performer's page" not in r.stdout + r.stderr


def test_a_page_named_as_a_device_is_the_only_page(tmp_path: Path) -> None:
    """`puppet live --device 'panel://127.0.0.1:PORT?face=mesh'` served that page and the default
    one beside it (two URLs, the default on the next port); the named page is the show's page, and
    --panel-role gives it its roles."""
    import asyncio
    import re
    import socket

    import aiohttp

    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    proc = PuppetProcess("live", "--headless", "--duration", "60", "--device", f"panel://127.0.0.1:{port}?face=mesh",
                         "--panel-role", "mouth=jaw", cwd=tmp_path)

    async def hello() -> dict:
        async with aiohttp.ClientSession() as session, \
                session.ws_connect(f"http://127.0.0.1:{port}/ws?role=mouth&face=0") as ws:
            return json.loads((await ws.receive(timeout=30)).data)

    try:
        assert proc.url == f"http://127.0.0.1:{port}/"
        first = asyncio.run(hello())
        assert first["roles"] == ["mouth"] and "slider:jaw" in first["allowed"], first
        assert not any("zygomaticus" in c for c in first["allowed"]), first["allowed"]
    finally:
        out = proc.stop()
    assert len(re.findall(r"performer's page at http://", out)) == 1, out


def test_a_page_follows_the_show_through_a_restart(tmp_path: Path) -> None:
    """The show stops (a crash, a restart) while a performer's page is open: the page says so and
    shows no device as connected while nothing answers; the show started again on the same port
    is found by the page by itself, no slider stays frozen at what the page sent the old show, and
    the page drives the new one."""
    import socket

    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    show = PuppetProcess("live", "--headless", "--panel", str(port), "--duration", "120", "--record", "a.jsonl",
                         cwd=tmp_path)
    drv = browser()
    again = None
    try:
        drv.get(show.url + "?name=alice")
        wait_for(lambda: ticking(drv), 60, "the live loop's values on the page")
        drag(drv, "jaw", 0.7)
        wait_for(lambda: (applied(drv, "jaw") or 0) > 0.4, 10, "the jaw applied")
        assert drv.find_elements(By.CSS_SELECTOR, "#devices .dev.ok")
        show.stop()
        wait_for(lambda: "retrying" in drv.find_element(By.ID, "conn").text, 10, "the page saying it lost the show")
        wait_for(lambda: not drv.find_elements(By.CSS_SELECTOR, "#devices .dev.ok"), 10, "no device shown connected")
        again = PuppetProcess("live", "--headless", "--panel", str(port), "--duration", "120", "--record", "b.jsonl",
                              cwd=tmp_path)
        assert again.url == f"http://127.0.0.1:{port}/"  # the same port, although the old page's connection lingers
        wait_for(lambda: drv.find_element(By.ID, "conn").text == "connected", 30, "the page reconnected")
        wait_for(lambda: ticking(drv) and drv.find_elements(By.CSS_SELECTOR, "#devices .dev.ok"), 30,
                 "the new show's devices")
        assert drv.execute_script("return window.puppetPanel.own") == {}
        # the jaw's slider stands where the new show's jaw is (at rest), not at the old 0.7
        jaw = drv.find_element(By.CSS_SELECTOR, '.slider[data-channel="jaw"]')
        wait_for(lambda: float(jaw.get_attribute("aria-valuenow")) < 0.05, 10, "the jaw's slider at the face's jaw")
        drag(drv, "jaw", 0.5)
        wait_for(lambda: 0.3 < (applied(drv, "jaw") or 0) < 0.65, 10, "the jaw driven in the new show")
    finally:
        quit_browser(drv)
        if again is not None:
            again.stop()
        show.stop()
    evs = [r for r in records(tmp_path / "b.jsonl") if r["t"] == "ev"]
    assert any(r["ctl"] == "slider:jaw" and r["dev"].endswith("/alice") for r in evs)
