"""``hid://VID:PID[?serial=S&index=N]`` — USB HID boxes: a known profile when the product is
known, otherwise buttons and axes from the device's own report descriptor.

Hot-plug: when a read fails the handle is closed, and the device is looked up again by VID:PID
(and serial number, when given or seen at the first open) every ``reconnect_interval``.
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Iterable
from typing import Any

from devices.base import Device
from devices.errors import DeviceError, DeviceSpecError
from devices.events import ControlEvent
from devices.hid.descriptor import DescriptorError, GenericDecoder, ReportDescriptor
from devices.hid.profiles import Command, PowerMateProfile, Profile, profile_for
from devices.hid.transport import HidHandle, hid_api
from devices.spec import DeviceSpec


def parse_vid_pid(spec: DeviceSpec) -> tuple[int, int]:
    """``077d:0410`` (hex) -> (0x077d, 0x0410)."""
    vid, sep, pid = spec.location.partition(":")
    try:
        if not sep:
            raise ValueError
        return int(vid, 16), int(pid, 16)
    except ValueError:
        raise DeviceSpecError(f"{spec.text}: expected hid://VID:PID in hex, e.g. hid://077d:0410") from None


class HidDevice(Device):
    """A HID box. Options: ``serial`` (pick by serial number), ``index`` (the Nth match, 0-based),
    ``counts_per_turn`` (dials), ``generic=1`` (ignore the built-in profile)."""

    scheme = "hid"
    FORM = "hid://VID:PID[?serial=S&index=N&counts_per_turn=N&generic=1]"
    OPTIONS = frozenset({"serial", "index", "counts_per_turn", "generic"})
    #: Short reads bound how long a queued light command waits (hidapi reads cannot be woken).
    read_timeout = 0.02

    def __init__(self, spec: DeviceSpec, hid_api_module: Any = None, **options: Any) -> None:
        super().__init__(spec, **options)
        self.vid, self.pid = parse_vid_pid(spec)
        self.serial: str | None = spec.query.get("serial")
        self.index = spec.get_int("index", 0, lo=0)
        self.counts_per_turn = spec.get_int("counts_per_turn", 0, lo=0) or None
        self.force_generic = spec.get_bool("generic", False)
        self._api = hid_api_module
        self._handle: HidHandle | None = None
        self._outbox: deque[Command] = deque()
        self.decoder: Profile | GenericDecoder | None = None
        self.report_size = 64

    def _find(self, api: Any) -> dict[str, Any]:
        found = [d for d in api.enumerate(self.vid, self.pid)
                 if self.serial is None or (d.get("serial_number") or "") == self.serial]
        if self.index >= len(found):
            raise OSError(f"no HID device {self.vid:04x}:{self.pid:04x}"
                          + (f" with serial {self.serial}" if self.serial else "")
                          + (f" at index {self.index}" if self.index else ""))
        return found[self.index]

    def _open(self) -> None:
        api = self._api or hid_api()
        self._close_handle()  # never two handles on one device
        info = self._find(api)
        try:
            handle = HidHandle.open_path(api, info["path"])
        except OSError as err:
            raise OSError(f"cannot open {self.vid:04x}:{self.pid:04x}: {err} (permissions or a kernel driver? "
                          "see 'Permissions' in docs/devices.md)") from err
        self._handle = handle
        if self.serial is None and info.get("serial_number"):
            self.serial = info["serial_number"]  # come back to this very unit after an unplug
        if self.decoder is None:
            self._choose_decoder(handle, info)
        assert self.decoder is not None
        if isinstance(self.decoder, Profile):
            for cmd in self.decoder.init_commands():
                self._send(cmd)

    def _choose_decoder(self, handle: HidHandle, info: dict[str, Any]) -> None:
        profile = None if self.force_generic else profile_for(self.vid, self.pid, self.spec, self.warnings,
                                                              self.counts_per_turn)
        product = (info.get("product_string") or "").strip()
        if profile is not None:
            self.decoder, self.report_size = profile, profile.report_size
            self.description = f"{profile.name} ({self.vid:04x}:{self.pid:04x})"
        else:
            try:
                desc = ReportDescriptor.parse(handle.report_descriptor())
            except (OSError, DescriptorError) as err:
                raise DeviceError(f"{self.spec}: cannot read a usable report descriptor: {err}") from err
            decoder = GenericDecoder(self.spec, desc, self.counts_per_turn or 24, self.warnings)
            if not decoder.usable():
                raise DeviceError(f"{self.spec}: the report descriptor declares no buttons, axes or dials")
            self.decoder = decoder
            self.report_size = max(desc.report_bytes.values(), default=63) + 1
            self.description = f"{product or 'HID device'} ({self.vid:04x}:{self.pid:04x}, from its report descriptor)"
        self.controls = list(self.decoder.controls)

    def _read(self, timeout: float) -> Iterable[ControlEvent]:
        handle = self._handle
        if handle is None:
            raise OSError("not open")
        while self._outbox:
            self._send(self._outbox.popleft())
        data = handle.read(self.report_size, int(timeout * 1000))
        t = time.monotonic()
        if not data:
            return ()
        assert self.decoder is not None
        return self.decoder.decode(data, t)

    def _close_handle(self) -> None:
        handle, self._handle = self._handle, None
        if handle is not None:
            handle.close()

    def _send(self, cmd: Command) -> None:
        handle = self._handle
        if handle is None:
            return
        if cmd.kind == "feature":
            handle.send_feature_report(cmd.data)
        else:
            handle.write(cmd.data)

    def _set_light(self, control: str, level: float) -> None:
        """Queued for the reader thread: a USB write may take a while and the caller is the live loop."""
        if isinstance(self.decoder, Profile):
            self._outbox.extend(self.decoder.light(control, level))

    def set_pulse(self, on: bool, speed: int = 255) -> None:
        """PowerMate only: pulse the LED (speed 0..510, 255 normal); a no-op elsewhere."""
        if isinstance(self.decoder, PowerMateProfile) and self._connected:
            self._outbox.extend(self.decoder.pulse(on, speed))
