"""Screenshots of the performer's page and the force-graph editor for docs/images/: a live show
(`puppet live --headless --panel`), two pages (one limited to the mouth), a few moves; then the
editor on the take with keys made from the recording and one re-recorded pass; the face shown on
the pages (pictures of the show), the keyboard's focus ring on one slider.
Run: .venv/bin/python docs/make_panel_images.py   (needs chromium + chromium-driver)
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "tests" / "panel")]
OUT = ROOT / "docs" / "images"

from panel_browser import PuppetProcess, browser, quit_browser, wait_for  # noqa: E402
from selenium.webdriver.common.action_chains import ActionChains  # noqa: E402
from selenium.webdriver.common.by import By  # noqa: E402


def drag(drv, channel: str, frac: float) -> None:
    s = drv.find_element(By.CSS_SELECTOR, f'.slider[data-channel="{channel}"]')
    w = s.size["width"]
    ActionChains(drv).move_to_element_with_offset(s, -w // 2 + 2, 0).click_and_hold() \
        .move_by_offset(int(w * frac), 0).release().perform()


def main() -> int:
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        show = PuppetProcess("live", "--headless", "--panel", "0", "--duration", "60", "--record", "take.jsonl",
                             "--panel-role", "mouth=jaw,orbicularis_oris,zygomaticus_major,depressor_*,expr:happiness",
                             cwd=d)
        a, b = browser(), browser()
        try:
            a.get(show.url + "?name=alice&role=mouth")
            b.get(show.url + "?name=bob")
            for drv in (a, b):
                wait_for(lambda drv=drv: drv.execute_script("return window.puppetPanel.values !== null"), 60, "ticks")
            drag(b, "frontalis_inner_l", 0.6)
            time.sleep(0.8)
            drag(a, "jaw", 0.45)
            drag(a, "zygomaticus_major_l", 0.7)
            time.sleep(0.8)
            b.find_element(By.CSS_SELECTOR, 'button[data-control="pad:AU45"]')
            a.find_element(By.ID, "marker").click()
            drag(b, "eyes_yaw", 0.75)
            time.sleep(1.5)
            for drv in (a, b):
                wait_for(lambda drv=drv: drv.execute_script("return window.puppetPanel.face.drawn > 0"), 30, "the face")
            # the keyboard's focus ring on the jaw slider of the mouth page
            a.execute_script("document.querySelector('.slider[data-channel=\"jaw\"]').focus()")
            b.save_screenshot(str(OUT / "panel-live.png"))
            a.save_screenshot(str(OUT / "panel-live-role.png"))
        finally:
            quit_browser(a)
            quit_browser(b)
            show.stop()
        import subprocess

        script = ROOT / "examples" / "mock" / "sgi_rehearsal.toml"
        subprocess.run([sys.executable, "-m", "puppet", "live", "--device", f"mock://{script}?speed=0", "--headless",
                        "--duration", "12", "--record", "rehearsal.jsonl"], cwd=d, check=True, capture_output=True)
        ed = PuppetProcess("edit", "rehearsal.jsonl", "--port", "0", cwd=d)
        drv = browser()
        try:
            drv.get(ed.url)
            wait_for(lambda: drv.execute_script("return window.puppetEditor && window.puppetEditor.ready"), 30, "editor")
            drv.find_element(By.ID, "fromrec").click()
            drv.execute_script("const E = window.puppetEditor; const c = E.curves[0];"
                               "const n = c.keys.length, mid = c.keys.reduce((a, b) => b.v > a.v ? b : a);"
                               "E.sel = new Set(c.keys.filter((k) => Math.abs(k.t - mid.t) < 0.4)); E.api.setPlayhead(mid.t);"
                               "document.getElementById('pin').value = '9'; document.getElementById('pout').value = '11';")
            drv.find_element(By.CSS_SELECTOR, '#targets [data-arm="jaw"]').click()
            wait_for(lambda: drv.execute_script("return window.puppetEditor.face.drawn > 0"), 30, "the preview")
            time.sleep(2.0)
            drv.save_screenshot(str(OUT / "panel-editor.png"))
        finally:
            quit_browser(drv)
            ed.stop()
    print(f"wrote {OUT / 'panel-live.png'}, {OUT / 'panel-live-role.png'}, {OUT / 'panel-editor.png'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
