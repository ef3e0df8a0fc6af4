"""Turns hardware bytes into control events. Nothing in here knows about faces.

``open_device(spec)`` names a device by a URL-like spec and returns an opened ``Device``; each
started device runs one reader thread that hands ``ControlEvent``/``StatusEvent`` to listeners,
typically an ``EventQueue`` the live loop drains. Backends are imported lazily.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from devices.base import ControlInfo, Device, Listener
from devices.errors import DeviceError, DeviceSpecError
from devices.events import ControlEvent, StatusEvent
from devices.queue import EventQueue
from devices.registry import BACKENDS, backend_class, known_schemes, open_device
from devices.spec import DeviceSpec, parse_spec

if TYPE_CHECKING:
    from devices.discovery import DeviceInfo

__all__ = [
    "BACKENDS",
    "ControlEvent",
    "ControlInfo",
    "Device",
    "DeviceError",
    "DeviceInfo",
    "DeviceSpec",
    "DeviceSpecError",
    "EventQueue",
    "Listener",
    "StatusEvent",
    "backend_class",
    "discover",
    "known_schemes",
    "open_device",
    "parse_spec",
]


def discover(probe: bool = False) -> list[DeviceInfo]:
    """What is plugged in: serial ports, HID devices, CAN channels (see devices.discovery)."""
    from devices.discovery import discover as _discover

    return _discover(probe=probe)


def __getattr__(name: str) -> Any:
    if name == "DeviceInfo":
        from devices.discovery import DeviceInfo

        return DeviceInfo
    raise AttributeError(name)
