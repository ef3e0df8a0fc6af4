"""The performer's page and the editor for keyboard, screen-reader and touch users, in real headless
chromium: every control reached by Tab, sliders moved by their keys until the live loop applies the
values, a linked pair announced and unlinked, panic pressed from the keyboard and recorded, two
fingers on two sliders at once; axe-core (npm, installed by .ci/setup) finds no serious or critical
violation on either page."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from panel_browser import PuppetProcess, axe_violations, browser, quit_browser, wait_for
from selenium.webdriver.common.action_chains import ActionChains
from selenium.webdriver.common.by import By
from selenium.webdriver.common.keys import Keys


@pytest.fixture(scope="module")
def show(tmp_path_factory: pytest.TempPathFactory):
    d = tmp_path_factory.mktemp("access")
    proc = PuppetProcess("live", "--headless", "--panel", "0", "--duration", "120", "--record", "take.jsonl", cwd=d)
    yield proc, d
    proc.stop()


def applied(drv, channel: str) -> float:
    return drv.execute_script("const p = window.puppetPanel; return p.values[p.index[arguments[0]]];", channel)


def slider(drv, channel: str):
    return drv.find_element(By.CSS_SELECTOR, f'.slider[data-channel="{channel}"]')


def keys(drv, element, *pressed: str) -> None:
    drv.execute_script("arguments[0].focus()", element)
    chain = ActionChains(drv)
    for k in pressed:
        chain.send_keys(k)
    chain.perform()


def test_keyboard_reaches_every_control_and_drives_the_face(show) -> None:
    proc, d = show
    drv = browser()
    try:
        drv.get(proc.url + "?name=keys")
        wait_for(lambda: drv.execute_script("return window.puppetPanel.values !== null"), 60, "the live values")
        # Tab from the top walks through every control: the sliders (each channel, the age dial), the
        # L=R toggles, the pads, panic
        drv.execute_script("window._seen = []; document.addEventListener('focusin', (e) => { const t = e.target;"
                           "window._seen.push([t.getAttribute('role') || t.tagName.toLowerCase(), t.dataset.channel ||"
                           " t.dataset.control || t.id || t.getAttribute('aria-label') || '']); });")
        n_channels = drv.execute_script("return window.puppetPanel.layout.channels.length")
        ActionChains(drv).send_keys(*([Keys.TAB] * (n_channels * 2 + 80))).perform()
        seen = drv.execute_script("return window._seen")
        sliders = {name for role, name in seen if role == "slider"}
        assert sliders >= {c for c in drv.execute_script(
            "return window.puppetPanel.layout.channels.map(c => c.name)") if c != "age"}
        assert ["slider", "age"] in seen
        assert ["button", "panic"] in seen and ["button", "marker"] in seen
        assert any(r == "button" and n.startswith("pad:AU") for r, n in seen)
        assert any(r == "button" and n.startswith("L=R ") for r, n in seen)
        # the jaw by its keys: End, Home, Page Up, three arrows; the loop applies each
        jaw = slider(drv, "jaw")
        assert jaw.get_attribute("role") == "slider" and jaw.get_attribute("aria-valuemin") == "0"
        for pressed, want in (((Keys.END,), 1.0), ((Keys.HOME,), 0.0), ((Keys.PAGE_UP,), 0.1),
                              ((Keys.ARROW_RIGHT,) * 3, 0.13), ((Keys.ARROW_DOWN,), 0.12)):
            keys(drv, jaw, *pressed)
            wait_for(lambda want=want: abs(applied(drv, "jaw") - want) < 1e-3, 10, f"the jaw applied at {want}")
            assert float(jaw.get_attribute("aria-valuenow")) == pytest.approx(want)
        # a slider at its end: its number over the full fill is still readable (axe's contrast)
        keys(drv, jaw, Keys.END)
        wait_for(lambda: abs(applied(drv, "jaw") - 1.0) < 1e-3, 10, "the jaw applied at its end")
        bad = axe_violations(drv)
        assert bad == [], bad
        # a pair moves together and says so; L=R pressed from the keyboard unlinks it
        left, right = slider(drv, "zygomaticus_major_l"), slider(drv, "zygomaticus_major_r")
        assert "left and right together" in left.get_attribute("aria-valuetext")
        keys(drv, left, Keys.PAGE_UP, Keys.PAGE_UP, Keys.PAGE_UP)
        wait_for(lambda: abs(applied(drv, "zygomaticus_major_r") - 0.3) < 1e-3, 10, "the right side following the left")
        link = drv.find_element(By.CSS_SELECTOR, 'button[aria-label^="L=R zygomaticus_major"]')
        assert link.get_attribute("aria-pressed") == "true"
        keys(drv, link, Keys.SPACE)
        assert link.get_attribute("aria-pressed") == "false"
        assert "together" not in left.get_attribute("aria-valuetext")
        keys(drv, left, Keys.PAGE_UP)
        wait_for(lambda: abs(applied(drv, "zygomaticus_major_l") - 0.4) < 1e-3, 10, "the left side alone")
        assert applied(drv, "zygomaticus_major_r") == pytest.approx(0.3, abs=1e-3)
        # an AU pad held with the space bar is pressed while held
        au = drv.find_element(By.CSS_SELECTOR, 'button[data-control="pad:AU45"]')
        drv.execute_script("arguments[0].focus()", au)
        ActionChains(drv).key_down(Keys.SPACE).perform()
        assert au.get_attribute("aria-pressed") == "true"
        ActionChains(drv).key_up(Keys.SPACE).perform()
        assert au.get_attribute("aria-pressed") == "false"
        # panic from the keyboard: Enter on the button; the face eases back to neutral
        keys(drv, drv.find_element(By.ID, "panic"), Keys.ENTER)
        wait_for(lambda: applied(drv, "zygomaticus_major_l") < 1e-3 and applied(drv, "jaw") < 1e-3, 10, "panic")
        # the focused control shows a ring
        ring = drv.execute_script("const b = document.getElementById('panic'); b.focus();"
                                  "const s = getComputedStyle(b); return [s.outlineStyle, s.outlineWidth];")
        assert ring[0] != "none" and float(ring[1].rstrip("px")) >= 2
        bad = axe_violations(drv)
        assert bad == [], bad
    finally:
        quit_browser(drv)
    take = [json.loads(x) for x in (d / "take.jsonl").read_text().splitlines() if x.strip()]
    evs = [r for r in take if r["t"] == "ev" and str(r.get("dev", "")).endswith("/keys")]
    assert {r["ctl"] for r in evs} >= {"slider:jaw", "slider:zygomaticus_major_l", "button:panic", "pad:AU45"}


def test_two_fingers_on_two_sliders(show) -> None:
    """Touch: two fingers down on two sliders at once, both slide; each slider follows its own."""
    proc, _ = show
    drv = browser()
    try:
        drv.get(proc.url + "?name=touch")
        wait_for(lambda: drv.execute_script("return window.puppetPanel.values !== null"), 60, "the live values")
        boxes = drv.execute_script(
            "return ['jaw', 'orbicularis_oris'].map(c => { const r = document.querySelector("
            "`.slider[data-channel=\"${c}\"]`).getBoundingClientRect(); return [r.left, r.top + r.height / 2, r.width]; })")

        def touch(kind: str, fracs: list[float]) -> None:
            pts = [{"x": x + w * f, "y": y, "id": i} for i, ((x, y, w), f) in enumerate(zip(boxes, fracs))]
            drv.execute_cdp_cmd("Input.dispatchTouchEvent", {"type": kind, "touchPoints": [] if kind == "touchEnd" else pts})

        touch("touchStart", [0.1, 0.1])
        for k in range(1, 6):
            touch("touchMove", [0.1 + 0.1 * k, 0.1 + 0.05 * k])
        touch("touchEnd", [])
        own = drv.execute_script("return window.puppetPanel.own")
        assert own["slider:jaw"] == pytest.approx(0.6, abs=0.02)
        assert own["slider:orbicularis_oris"] == pytest.approx(0.35, abs=0.02)
        wait_for(lambda: abs(applied(drv, "jaw") - own["slider:jaw"]) < 1e-3, 10, "the jaw applied")
    finally:
        quit_browser(drv)


def test_editor_by_keyboard_and_axe(show, tmp_path: Path) -> None:
    proc, d = show
    import shutil

    take = tmp_path / "take.jsonl"
    wait_for(lambda: (d / "take.jsonl").stat().st_size > 0, 10, "the take")
    # the take recorded so far, cut at its last whole line, as the page's editor button does
    text = (d / "take.jsonl").read_text()
    take.write_text(text[:text.rfind("\n") + 1])
    ed = PuppetProcess("edit", take.name, "--port", "0", cwd=tmp_path)
    drv = browser()
    js = drv.execute_script
    try:
        drv.get(ed.url)
        wait_for(lambda: js("return window.puppetEditor && window.puppetEditor.ready"), 60, "the editor")
        # a graph chosen and armed from the keyboard; the list keeps the focus where it was
        mentalis = drv.find_element(By.CSS_SELECTOR, '#targets [data-target="mentalis"]')
        keys(drv, mentalis, Keys.ENTER)
        assert js("return window.puppetEditor.target") == "mentalis"
        assert js("return document.activeElement.dataset.target") == "mentalis"
        arm = drv.find_element(By.CSS_SELECTOR, '#targets [data-arm="mentalis"]')
        keys(drv, arm, Keys.SPACE)
        assert js("return [...window.puppetEditor.armed]") == ["mentalis"]
        assert js("return document.activeElement.dataset.arm") == "mentalis"
        # on the graph: Enter inserts a key at the playhead, Page Up raises it by a tenth of the range
        graph = drv.find_element(By.ID, "graph")
        keys(drv, graph, Keys.ENTER, Keys.PAGE_UP, Keys.ARROW_UP)
        ks = js("return window.puppetEditor.curves.filter(c => c.target === 'mentalis').flatMap(c => c.keys).map(k => k.v)")
        assert len(ks) == 1 and ks[0] == pytest.approx(0.11, abs=1e-6)
        assert "value 0.110" in drv.find_element(By.ID, "graphstatus").get_attribute("textContent")
        bad = axe_violations(drv)
        assert bad == [], bad
    finally:
        quit_browser(drv)
        ed.stop()
    shutil.rmtree(tmp_path, ignore_errors=True)
