"""The performer's page lists the take library: a real `puppet live` serving the page and a
headless chromium searching the takes, exporting one (the file equals `puppet replay --out`'s)
and opening one in the editor."""

from __future__ import annotations

import sys
import time
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "panel"))
from panel_browser import PuppetProcess, browser, quit_browser, wait_for  # noqa: E402
from selenium.webdriver.common.by import By  # noqa: E402

from puppet.cli import main  # noqa: E402
from puppet.library.store import Library  # noqa: E402
from takes import write_take  # noqa: E402


def test_page_searches_exports_and_edits_takes(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    lib = tmp_path / "takes.db"
    ana = write_take(tmp_path / "shoot" / "ana_smile.jsonl", ticks=40, seed=1, performer="ana")
    bob = write_take(tmp_path / "shoot" / "bob_jaw.jsonl", ticks=40, seed=2, performer="bob")
    with Library(lib) as library:
        library.register(ana)
        library.register(bob)
    show = PuppetProcess("live", "--headless", "--panel", "0", "--duration", "120", "--library", str(lib), cwd=tmp_path)
    drv = browser()
    try:
        drv.get(show.url)
        items = lambda: drv.find_elements(By.CSS_SELECTOR, "#takes-list li")  # noqa: E731
        wait_for(lambda: len(items()) == 2, 30, "both takes listed")
        box = drv.find_element(By.ID, "takes-q")
        assert drv.find_element(By.CSS_SELECTOR, "label[for=takes-q]").is_displayed()
        box.send_keys("performer:bob")
        drv.find_element(By.CSS_SELECTOR, "#takes-form button").click()
        wait_for(lambda: len(items()) == 1 and "bob_jaw" in items()[0].text, 20, "the search result")
        items()[0].find_element(By.CSS_SELECTOR, "button[aria-label$='to csv']").click()
        out = bob.with_suffix(".csv")
        wait_for(lambda: "exported" in drv.find_element(By.ID, "takes-status").text, 90, "the export to finish")
        assert main(["replay", str(bob), "--out", str(tmp_path / "single.csv")]) == 0
        assert out.read_bytes() == (tmp_path / "single.csv").read_bytes()
        before = set(drv.window_handles)
        items()[0].find_element(By.CSS_SELECTOR, "button[aria-label^='edit take']").click()
        wait_for(lambda: len(set(drv.window_handles) - before) == 1, 30, "the editor's tab")
        drv.switch_to.window((set(drv.window_handles) - before).pop())
        wait_for(lambda: "bob_jaw" in drv.page_source or drv.current_url.startswith("http://127.0.0.1"), 60,
                 "the editor to load")
        assert drv.current_url.startswith("http://127.0.0.1:") and drv.current_url != show.url
    finally:
        quit_browser(drv)
        show.stop()
        time.sleep(0.2)
