"""Scheme -> backend registry with lazy imports and the ``puppet.devices`` entry-point group.

Importing ``devices`` never imports hidapi, python-can or glfw: a backend module is imported only
when a spec names its scheme, so a missing optional library fails that one spec, clearly.
"""

from __future__ import annotations

import importlib
import logging
from typing import Any

from devices.base import Device
from devices.errors import DeviceError, DeviceSpecError
from devices.spec import parse_spec

log = logging.getLogger("devices")

#: Built-in backends: scheme -> (module, class name).
BACKENDS: dict[str, tuple[str, str]] = {
    "sgi": ("devices.sgi", "SgiDevice"),
    "firmata": ("devices.firmata", "FirmataDevice"),
    "serial": ("devices.textserial", "TextSerialDevice"),
    "hid": ("devices.hid.device", "HidDevice"),
    "can": ("devices.candev", "CanDevice"),
    "keyboard": ("devices.keyboard", "KeyboardDevice"),
    "mock": ("devices.mock", "MockDevice"),
    "midi": ("devices.midi.port", "MidiPortDevice"),
    "rawmidi": ("devices.midi.raw", "RawMidiDevice"),
    "osc": ("devices.osc", "OscDevice"),
    "audio": ("devices.audio.device", "AudioDevice"),
    "facecap": ("devices.facestream.facecap", "FaceCapDevice"),
    "vmc": ("devices.facestream.vmc", "VmcDevice"),
    "ifacialmocap": ("devices.facestream.ifacialmocap", "IFacialMocapDevice"),
    "livelink": ("devices.facestream.livelink", "LiveLinkDevice"),
    "panel": ("puppet.panel.device", "PanelDevice"),  # the browser page; its server lives in puppet/panel
}

ENTRY_POINT_GROUP = "puppet.devices"


def entry_points(group: str) -> Any:
    """importlib.metadata's entry points of `group`, imported on first use: only a scheme that is
    not built in needs them, and importing importlib.metadata costs ~15 ms of every start."""
    from importlib.metadata import entry_points as find

    return find(group=group)


def _plugin_backends() -> dict[str, tuple[str, str]]:
    """Third-party backends declared as ``scheme = "module:Class"`` in the entry-point group."""
    found: dict[str, tuple[str, str]] = {}
    try:
        eps = entry_points(group=ENTRY_POINT_GROUP)
    except Exception as err:  # broken metadata must not break built-in devices
        log.warning("cannot read %s entry points: %s", ENTRY_POINT_GROUP, err)
        return found
    for ep in eps:
        module, _, attr = ep.value.partition(":")
        if module and attr:
            found[ep.name.lower()] = (module.strip(), attr.strip())
    return found


def known_schemes() -> list[str]:
    """Every scheme a spec may use, built-in and plugged in."""
    return sorted(set(BACKENDS) | set(_plugin_backends()))


def backend_class(scheme: str) -> type[Device]:
    """Import and return the class for ``scheme``; DeviceSpecError for an unknown scheme."""
    target = BACKENDS.get(scheme) or _plugin_backends().get(scheme)
    if target is None:
        raise DeviceSpecError(
            f"unknown device scheme {scheme!r}; expected one of {', '.join(known_schemes())} "
            "(SCHEME://LOCATION[?OPTIONS])"
        )
    module_name, class_name = target
    try:
        module = importlib.import_module(module_name)
        cls = getattr(module, class_name)
    except (ImportError, AttributeError) as err:
        raise DeviceError(f"backend {scheme!r} ({module_name}:{class_name}) cannot be loaded: {err}") from err
    if not (isinstance(cls, type) and issubclass(cls, Device)):
        raise DeviceError(f"backend {scheme!r} ({module_name}:{class_name}) is not a devices.Device")
    return cls


def open_device(spec: str, *, require: bool | str = True, **options: Any) -> Device:
    """Parse ``spec``, build its backend and open it (the reader thread is not started).

    With ``require=False`` a device that is not plugged in yet is returned unconnected; once
    started it connects by itself when it appears. With ``require="present"`` a device whose
    address exists but which failed to open (a box powering up, a flaky first contact) is returned
    unconnected too, while one whose address is not there is an error. ``options`` go to the backend (e.g. a mock's
    ``clock``).
    """
    parsed = parse_spec(spec)
    cls = backend_class(parsed.scheme)
    device = cls(parsed, **options)
    try:
        device.open()
    except DeviceError as err:
        if require == "present" and device.address_exists():
            log.info("%s: %s; will connect once it answers", spec, err)
            return device
        if require:
            device.close()
            raise
        log.info("%s: not present yet; will connect when it appears", spec)
    return device
