"""The performer's page: a control panel and the force-graph editor in the browser.

`device` (the ``panel://`` backend: each page is a control box), `server` (aiohttp, security),
`layout` (what the page shows and the map of its controls), `editor` (`puppet edit TAKE.jsonl`),
`static/` (plain HTML, JS and CSS shipped in the package: no build step, no network).
See docs/panel.md."""

from __future__ import annotations

import sys
from collections.abc import Sequence
from typing import Any


def panel_devices(devs: Sequence[Any]) -> list[Any]:
    return [d for d in devs if getattr(d, "scheme", "") == "panel"]


def with_panel_map(spec: Any, vocab: Any, devs: Sequence[Any]) -> Any:
    """The mapping plus the page's bindings when a page device is open; a page control the map
    already binds itself (e.g. written by `puppet learn`) keeps the map's binding only."""
    if not panel_devices(devs):
        return spec
    from dataclasses import replace

    from puppet.mapping.defaults import merge
    from puppet.panel.layout import panel_map

    page = panel_map(vocab)
    taken = {b.control for b in spec.bindings if (b.device or "").startswith("panel")}
    page = replace(page, bindings=[b for b in page.bindings if b.control not in taken])
    return merge([(spec, None), (page, None)], spec.source)


def announce(dev: Any, out: Any = None) -> None:
    """Print the page's URL (and, served to the LAN, its QR code)."""
    from puppet.panel.server import qr_text

    out = out or sys.stdout
    srv = dev.server
    print(f"puppet: performer's page at {dev.url}", file=out, flush=True)
    if srv is not None and srv.lan:
        qr = qr_text(dev.url)
        if qr:
            print(qr, file=out, flush=True)
        print("puppet: the page is served to the LAN; anyone with this URL (it holds the token) can perform",
              file=out, flush=True)
