"""Device errors. `devices` depends on nothing else in the project, so the base lives here and
`puppet.errors.PuppetError` is not imported: the application catches `DeviceError` alongside it."""

from __future__ import annotations


class DeviceError(Exception):
    """A device could not be opened, or failed while in use. The message names the device spec."""


class DeviceSpecError(DeviceError, ValueError):
    """A device spec string is malformed or names an unknown scheme; the message shows the form."""
