"""``puppet devices`` (what is plugged in) and ``puppet monitor SPEC`` (every event of one device).

``monitor --json`` prints one JSON object per line; outside tools rely on the format:
control events ``{"t", "device", "control", "kind", "value", ["delta" for dials], "raw"}``,
status changes ``{"status": "connected"|"lost", "device", "t"}``.
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import sys
import time
from typing import Any


def register(subparsers: Any) -> None:
    """Add the ``devices`` and ``monitor`` subcommands."""
    p = subparsers.add_parser("devices", help="list connected control boxes",
                              description="List serial ports, HID devices, CAN channels, MIDI ports (ALSA and JACK) and "
                              "audio inputs usable as control boxes, and the keyboard fallback.")
    p.add_argument("--json", action="store_true", help="one JSON object per device")
    p.add_argument("--probe", action="store_true",
                   help="talk to serial ports/HID devices to recognise SGI boxes, Firmata boards and HID panels")
    p.set_defaults(func=run_devices)

    m = subparsers.add_parser("monitor", help="print every event of one device",
                              description="Open a device spec and print each control and status event.")
    m.add_argument("spec", help="device spec, e.g. sgi:///dev/ttyUSB0, hid://077d:0410, mock://script.toml")
    m.add_argument("--json", action="store_true", help="one JSON object per line")
    m.add_argument("--duration", type=float, default=None, metavar="S", help="stop after S seconds")
    m.add_argument("--wait", action="store_true", help="wait for a device that is not plugged in yet")
    m.set_defaults(func=run_monitor)


def _setup_logging() -> None:
    logging.basicConfig(level=logging.WARNING, format="puppet: warning: %(message)s", stream=sys.stderr)


def run_devices(args: argparse.Namespace) -> int:
    """List what ``devices.discover`` finds."""
    _setup_logging()
    from devices import discover

    infos = discover(probe=args.probe)
    if args.json:
        for info in infos:
            print(json.dumps({"spec": info.spec, "description": info.description, "kind": info.kind,
                              "usable": info.usable}), flush=True)
        return 0
    if not infos:
        print("no control boxes found (the keyboard:// fallback always works)")
        return 0
    width = max(len(i.spec) for i in infos)
    for info in infos:
        mark = "" if info.usable else "  (not usable as a control box)"
        print(f"{info.spec:<{width}}  {info.kind:<7} {info.description}{mark}")
    return 0


def event_to_json(event: Any) -> dict[str, Any]:
    """The documented JSON shape of one event."""
    from devices import StatusEvent

    if isinstance(event, StatusEvent):
        return {"status": event.status, "device": event.device, "t": event.t}
    out: dict[str, Any] = {"t": event.t, "device": event.device, "control": event.control,
                           "kind": event.kind, "value": event.value}
    if event.kind == "dial":
        out["delta"] = event.delta
    out["raw"] = event.raw
    return out


def _format_text(event: Any) -> str:
    from devices import StatusEvent

    if isinstance(event, StatusEvent):
        detail = f" ({event.detail})" if event.detail else ""
        return f"{event.t:14.6f}  {event.device}  *** {event.status}{detail}"
    delta = f"  delta {event.delta:+g}" if event.delta is not None else ""
    return f"{event.t:14.6f}  {event.device}  {event.control:<12} {event.kind:<6} {event.value:+.4f}{delta}  raw={event.raw!r}"


def run_monitor(args: argparse.Namespace) -> int:
    """Open the device, print events until the duration ends, the script ends or Ctrl-C."""
    _setup_logging()
    from devices import EventQueue, open_device
    from puppet.errors import PuppetError

    if args.duration is not None and not (args.duration >= 0 and math.isfinite(args.duration)):
        # nan or -1 ended the monitor at once, silently, exit 0 (0 opens the device, checks it and ends)
        raise PuppetError(f"--duration must be 0 or a positive number of seconds, got {args.duration}")
    device = open_device(args.spec, require=not args.wait)
    if getattr(device, "scheme", "") == "panel" and getattr(device, "server", None) is not None:
        from puppet.panel import announce

        announce(device)  # its URL (with the LAN mode's token: the page is unreachable without it)
    queue = EventQueue()
    device.add_listener(queue)
    end = None if args.duration is None else time.monotonic() + args.duration
    try:
        device.start()
        while end is None or time.monotonic() < end:
            wait = 0.1 if end is None else max(0.0, min(0.1, end - time.monotonic()))
            event = queue.get(timeout=wait)
            if event is None:
                if device.exhausted and len(queue) == 0:
                    break
                continue
            line = json.dumps(event_to_json(event)) if args.json else _format_text(event)
            try:
                print(line, flush=True)
            except BrokenPipeError:  # `puppet monitor ... | head`: the reader left, so do we
                import os

                os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
                break
    finally:
        device.close()
    return 0
