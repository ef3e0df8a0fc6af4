"""Turns hardware bytes into control events. Nothing in here knows about faces."""

from devices.errors import DeviceError, DeviceSpecError
from devices.events import ControlEvent, StatusEvent

__all__ = ["ControlEvent", "DeviceError", "DeviceSpecError", "StatusEvent"]
