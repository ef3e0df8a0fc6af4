"""The force-graph editor end to end: `puppet edit TAKE.jsonl` in its own process, a headless
chromium page moving a key and re-recording one armed channel between punch-in and punch-out;
the saved curves replay over the untouched take, and only what was edited changed."""

from __future__ import annotations

import hashlib
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from panel_browser import CHILD_ENV, ROOT, PuppetProcess, browser, quit_browser, wait_for
from selenium.webdriver.common.action_chains import ActionChains
from selenium.webdriver.common.by import By
from selenium.webdriver.common.keys import Keys

SCRIPT = ROOT / "examples" / "mock" / "sgi_rehearsal.toml"


@pytest.fixture(scope="module")
def take(tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("take")
    subprocess.run([sys.executable, "-m", "puppet", "live", "--device", f"mock://{SCRIPT}?speed=0", "--headless",
                    "--duration", "6", "--record", "take.jsonl"], cwd=d, check=True, capture_output=True,
                   env=CHILD_ENV)
    return d / "take.jsonl"


def test_edit_a_key_and_rerecord_one_channel(take: Path) -> None:
    from puppet.curves import load_curves
    from puppet.replay import Replayer, build_performance, state_digest
    from puppet.session import read_session

    before = hashlib.sha1(take.read_bytes()).hexdigest()
    base = build_performance(read_session(take), None)
    names = [c.name for c in base.face.vocab.channels]
    moving = [n for j, n in enumerate(names) if not np.all(base.values[:, j] == base.values[0, j])]
    edited = next(n for n in moving if n.endswith("_l"))[:-2]  # a pair the take moves
    armed = "jaw" if "jaw" not in moving else "mentalis"
    ed = PuppetProcess("edit", take.name, "--port", "0", cwd=take.parent)
    drv = browser()
    try:
        drv.get(ed.url)
        wait_for(lambda: drv.execute_script("return window.puppetEditor && window.puppetEditor.ready"), 30, "the editor")
        # keys from the recorded values, then drag the key nearest the middle of the take up
        drv.find_element(By.CSS_SELECTOR, f'#targets [data-target="{edited}"]').click()
        drv.find_element(By.ID, "fromrec").click()
        n_keys = drv.execute_script("return window.puppetEditor.curves[0].keys.length")
        assert 2 <= n_keys < base.ticks  # reduced at the tolerance
        i = n_keys // 2
        canvas = drv.find_element(By.ID, "graph")
        x, y = drv.execute_script(f"return window.puppetEditor.keyPixel('{edited}', {i})")
        ActionChains(drv).move_to_element_with_offset(canvas, int(x), int(y)).click_and_hold() \
            .move_by_offset(0, -60).release().perform()
        drv.find_element(By.ID, "lockvalue")  # the lock buttons exist
        wait_for(lambda: drv.execute_script("return window.puppetEditor.undo.length") >= 2, 5, "the move on the undo stack")
        # arm one channel, punch 1.0 .. 2.0 s, record while its slider is moved
        drv.find_element(By.CSS_SELECTOR, f'#targets [data-arm="{armed}"]').click()
        for field, val in (("pin", "1.0"), ("pout", "2.0")):
            el = drv.find_element(By.ID, field)
            el.clear()
            el.send_keys(val)
        slider = drv.find_element(By.CSS_SELECTOR, f'input[data-armed="{armed}"]')
        w = slider.size["width"]
        # the performer's slider is placed before the pass (at its top, from the keyboard) and moved
        # during it (a click at 30 %)
        slider.send_keys(Keys.END)
        wait_for(lambda: slider.get_attribute("value") == "1000", 5, "the slider at its top")
        drv.find_element(By.ID, "record").click()
        ActionChains(drv).move_to_element_with_offset(slider, int(w * 0.3) - w // 2, 0).click().perform()
        wait_for(lambda: drv.execute_script("return window.puppetEditor.lastRecord"), 20, "the recorded pass")
        drv.find_element(By.ID, "save").click()
        wait_for(lambda: (take.parent / "take.curves").exists(), 10, "the saved curves")
        drv.save_screenshot(str(take.parent / "editor.png"))
    finally:
        quit_browser(drv)
        ed.stop()
    assert hashlib.sha1(take.read_bytes()).hexdigest() == before  # the take is never written
    curves = load_curves(take.parent / "take.curves")
    assert curves.version == 2 and curves.take is not None and curves.take[0] == "take.jsonl"
    perf = build_performance(read_session(take), curves)
    diff = {names[j] for j in range(len(names)) if not np.array_equal(perf.values[:, j], base.values[:, j])}
    assert diff == {f"{edited}_l", f"{edited}_r", armed}
    col = names.index(armed)
    changed = np.flatnonzero(perf.values[:, col] != base.values[:, col])
    assert changed.min() >= 60 and changed.max() <= 120  # only between punch-in and punch-out
    assert perf.values[60, col] > 0.5  # where the slider was at punch-in
    # the pass is its own curve from punch-in to punch-out: no ramp from a key before it, the tick
    # before punch-in is the take's own, the punch-in tick is the pass's first key exactly
    (pass_,) = [c for c in curves.curves if c.target == armed]
    assert pass_.times[0] == pytest.approx(1.0) and pass_.times[-1] == pytest.approx(2.0)
    assert perf.values[59, col] == base.values[59, col] and perf.values[60, col] == pass_.values[0]
    # the edited performance replays the same bits twice, and the take alone still verifies
    digests = []
    for _ in range(2):
        rp = Replayer(perf)
        rp.seek(perf.ticks)
        digests.append(state_digest(rp.state))
    assert digests[0] == digests[1]
    rp = Replayer(base)
    rp.seek(base.ticks)
    assert base.checks and not rp.mismatches
    out = subprocess.run([sys.executable, "-m", "puppet", "replay", str(take), "--curves", str(take.parent / "take.curves"),
                          "--headless"], capture_output=True, text=True, env=CHILD_ENV)
    assert out.returncode == 0 and digests[0] in out.stdout


def test_editor_operations_overdub_and_export(take: Path) -> None:
    """Box select, delete, undo/redo, copy/paste, a step segment, snapping to seconds, key
    reduction, an overdub pass and a CSV export, through the page's own controls."""
    from selenium.webdriver.common.keys import Keys

    from puppet.curves import load_curves

    (take.parent / "take.curves").unlink(missing_ok=True)  # start from the bare take
    ed = PuppetProcess("edit", take.name, "--port", "0", cwd=take.parent)
    drv = browser()
    js = drv.execute_script
    try:
        drv.get(ed.url)
        wait_for(lambda: js("return window.puppetEditor && window.puppetEditor.ready"), 30, "the editor")
        wait_for(lambda: js("return window.puppetEditor.face.drawn") > 0, 30, "the preview's face drawn")
        drv.find_element(By.CSS_SELECTOR, '#targets [data-target="mentalis"]').click()
        for t, v in ((0.5, 0.2), (1.0, 0.4), (1.5, 0.6), (2.0, 0.8)):
            js(f"window.puppetEditor.api.insertKey({t}, {v})")
        keys = lambda: js("return window.puppetEditor.curves.filter(c => c.target === 'mentalis')"  # noqa: E731
                          ".flatMap(c => c.keys).map(k => [k.t, k.v, k.seg])")
        assert len(keys()) == 4
        # box-select the two middle keys with a drag over the background, then delete them
        canvas = drv.find_element(By.ID, "graph")
        (x1, y1), (x2, y2) = js("return [window.puppetEditor.keyPixel('mentalis', 1), window.puppetEditor.keyPixel('mentalis', 2)]")
        ActionChains(drv).move_to_element_with_offset(canvas, int(x1) - 12, int(y2) - 12).click_and_hold() \
            .move_to_element_with_offset(canvas, int(x2) + 12, int(y1) + 12).release().perform()
        assert js("return window.puppetEditor.sel.size") == 2
        drv.find_element(By.ID, "del").click()
        assert [k[0] for k in keys()] == [0.5, 2.0]
        body = drv.find_element(By.TAG_NAME, "body")
        body.send_keys(Keys.CONTROL, "z")
        assert len(keys()) == 4
        body.send_keys(Keys.CONTROL, Keys.SHIFT, "z")
        assert len(keys()) == 2
        body.send_keys(Keys.CONTROL, "z")
        # the first key's segment becomes a step; copy it and paste at the playhead, snapped to seconds
        x0, y0 = js("return window.puppetEditor.keyPixel('mentalis', 0)")
        ActionChains(drv).move_to_element_with_offset(canvas, int(x0), int(y0)).click().perform()
        drv.find_element(By.CSS_SELECTOR, 'button[data-seg="step"]').click()
        body.send_keys(Keys.CONTROL, "c")
        from selenium.webdriver.support.ui import Select

        Select(drv.find_element(By.ID, "snap")).select_by_value("second")
        js("window.puppetEditor.api.setPlayhead(3.4)")
        body.send_keys(Keys.CONTROL, "v")
        ks = keys()
        assert [k[0] for k in ks] == [0.5, 1.0, 1.5, 2.0, 3.0] and ks[0][2] == "step" and ks[4][2] == "step"
        # reduction: four keys on one straight line lose the middle ones at any tolerance
        js("window.puppetEditor.sel.clear()")
        drv.find_element(By.ID, "reduce").click()
        assert [k[0] for k in keys()] == [0.5, 2.0, 3.0]
        # overdub: the input stood still, moved over ticks 10..19, stood still again
        samples = [0.1] * 10 + [0.1 + 0.03 * i for i in range(1, 11)] + [0.4] * 30
        js(f"window.puppetEditor.api.commitPass(60, {{'orbicularis_oris': {samples}}}, true)")
        passes = js("return window.puppetEditor.curves.filter(c => c.target === 'orbicularis_oris')"
                    ".map(c => [c.keys[0].t, c.keys[c.keys.length - 1].t])")
        assert passes == [[70 / 60, 79 / 60]]
        drv.find_element(By.ID, "save").click()
        wait_for(lambda: (take.parent / "take.curves").exists()
                 and "orbicularis_oris" in (take.parent / "take.curves").read_text(), 10, "saved")
        Select(drv.find_element(By.ID, "exportname")).select_by_value(".csv")
        drv.find_element(By.ID, "export").click()
        wait_for(lambda: (take.parent / "take-edit.csv").exists(), 60, "the CSV export")
    finally:
        quit_browser(drv)
        ed.stop()
    cs = load_curves(take.parent / "take.curves")
    assert any(c.segs and "step" in c.segs for c in cs.curves if c.target == "mentalis")
    header = (take.parent / "take-edit.csv").read_text().splitlines()[0]
    assert "mentalis" in header and "orbicularis_oris" in header


def test_preview_after_an_edit_matches_a_fresh_replay(take: Path) -> None:
    """The preview keeps the states before the first edited tick; what it shows after an edit is
    bit for bit what a fresh replay of the edited take shows."""
    from puppet.panel.editor import Editor
    from puppet.replay import Replayer, state_digest

    (take.parent / "take.curves").unlink(missing_ok=True)
    ed = Editor(take)
    try:
        ed.performance()
        ed._seek(300)  # checkpoints up to 5 s
        ed.set_curves([{"target": "jaw", "keys": [[3.0, 0.1], [4.0, 0.7, "smooth"], [4.5, 0.2]]}])
        perf = ed.performance()
        assert 180 in ed._replayer.checkpoints and 240 not in ed._replayer.checkpoints
        for k in (250, 200, 290):
            fresh = Replayer(perf)
            fresh.seek(k)
            assert state_digest(ed._seek(k).state) == state_digest(fresh.state)
    finally:
        ed.close()


JAW_BOX = """impersonate = "sgi"
speed = 1.0
duration = 60.0
[[ramp]]
control = "dial7"
start = 0.0
duration = 60.0
from = 0.0
to = 1.0
rate = 60
"""


def test_rerecord_with_a_box(take: Path) -> None:
    """`puppet edit --device`: an armed graph follows the box's mapped value during the pass."""
    from puppet.curves import load_curves

    (take.parent / "take.curves").unlink(missing_ok=True)
    script = take.parent / "jawbox.toml"
    script.write_text(JAW_BOX)
    ed = PuppetProcess("edit", take.name, "--port", "0", "--device", f"mock://{script}", cwd=take.parent)
    drv = browser()
    js = drv.execute_script
    try:
        drv.get(ed.url)
        wait_for(lambda: js("return window.puppetEditor && window.puppetEditor.ready"), 30, "the editor")
        wait_for(lambda: js("return !!(window.puppetEditor.box && window.puppetEditor.box.driven.includes('jaw'))"),
                 30, "the box driving the jaw")
        drv.find_element(By.CSS_SELECTOR, '#targets [data-arm="jaw"]').click()
        js("document.getElementById('pin').value = '1'; document.getElementById('pout').value = '2';")
        drv.find_element(By.ID, "record").click()
        wait_for(lambda: js("return window.puppetEditor.lastRecord"), 20, "the recorded pass")
        drv.find_element(By.ID, "save").click()
        wait_for(lambda: (take.parent / "take.curves").exists(), 10, "the saved curves")
        assert "mock://" in drv.find_element(By.ID, "boxes").text
    finally:
        quit_browser(drv)
        ed.stop()
    (jaw,) = [c for c in load_curves(take.parent / "take.curves").curves if c.target == "jaw"]
    assert jaw.values[-1] > jaw.values[0] > 0.0  # the box kept turning through the pass
