"""The one place that calls hidapi (cython-hidapi, ``import hid``). Everything above it works on
bytes, so tests put a fake with the same methods as ``hid.device`` behind this wrapper."""

from __future__ import annotations

from types import ModuleType
from typing import Any


def hid_api() -> ModuleType:
    """The hidapi module; a DeviceError-friendly ImportError message if it is missing."""
    try:
        import hid
    except ImportError as err:  # pragma: no cover - hidapi is a core dependency
        raise ImportError("the hidapi package is needed for hid:// devices (pip install hidapi)") from err
    return hid


class HidHandle:
    """An open HID device: bytes in, bytes out, OSError on any failure (hidapi reports errors in
    three ways: raising, returning -1, returning an empty list on timeout)."""

    def __init__(self, dev: Any) -> None:
        self._dev = dev

    @classmethod
    def open_path(cls, api: Any, path: bytes) -> HidHandle:
        dev = api.device()
        dev.open_path(path)
        return cls(dev)

    def read(self, size: int, timeout_ms: int) -> bytes:
        """One input report, or b"" after ``timeout_ms`` (always > 0: 0 would block forever)."""
        try:
            data = self._dev.read(size, max(1, timeout_ms))
        except ValueError as err:  # "not open"
            raise OSError(str(err)) from err
        return bytes(data)

    def write(self, data: bytes) -> None:
        if self._dev.write(data) < 0:
            raise OSError(f"HID write failed: {self._error()}")

    def send_feature_report(self, data: bytes) -> None:
        if self._dev.send_feature_report(data) < 0:
            raise OSError(f"HID feature report failed: {self._error()}")

    def report_descriptor(self) -> bytes:
        return bytes(self._dev.get_report_descriptor())

    def _error(self) -> str:
        try:
            return str(self._dev.error())
        except Exception:
            return "unknown error"

    def close(self) -> None:
        try:
            self._dev.close()
        except Exception:
            pass
