"""A stand-in for the ``hid`` module (cython-hidapi) at its object boundary: ``enumerate()`` and
``device()`` objects with the same methods as ``hid.device``, serving canned report bytes."""

from __future__ import annotations

import queue
import threading
from typing import Any


class FakeHidUnit:
    """One plugged-in unit: its enumerate() entry, descriptor and the reports it will send."""

    def __init__(self, vid: int, pid: int, serial: str = "", descriptor: bytes = b"", product: str = "Fake",
                 path: bytes | None = None) -> None:
        self.info = {"path": path or f"fake-{vid:04x}-{pid:04x}-{serial}".encode(), "vendor_id": vid,
                     "product_id": pid, "serial_number": serial, "product_string": product,
                     "manufacturer_string": "", "usage_page": 0, "usage": 0, "interface_number": 0}
        self.descriptor = descriptor
        self.reports: queue.Queue[list[int]] = queue.Queue()
        self.plugged = True
        self.written: list[bytes] = []
        self.features: list[bytes] = []
        self.opens = 0
        self.changed = threading.Condition()

    def send(self, report: bytes | list[int]) -> None:
        self.reports.put(list(report))

    def wait_written(self, pred: Any, timeout: float = 5.0) -> None:
        with self.changed:
            assert self.changed.wait_for(lambda: pred(self), timeout), (self.written, self.features)


class FakeHidDevice:
    """Same methods as ``hid.device``: open_path, read, write, send_feature_report,
    get_report_descriptor, error, close."""

    def __init__(self, api: FakeHidApi) -> None:
        self.api = api
        self.unit: FakeHidUnit | None = None

    def open_path(self, path: bytes) -> None:
        for unit in self.api.units:
            if unit.plugged and unit.info["path"] == path:
                self.unit = unit
                unit.opens += 1
                return
        raise OSError("open failed")

    def _live(self) -> FakeHidUnit:
        if self.unit is None:
            raise ValueError("not open")
        return self.unit

    def read(self, max_length: int, timeout_ms: int = 0) -> list[int]:
        unit = self._live()
        try:
            report = unit.reports.get(timeout=timeout_ms / 1000)
        except queue.Empty:
            report = []
        if not unit.plugged:
            raise OSError("read error")
        return report[:max_length]

    def write(self, data: bytes | list[int]) -> int:
        unit = self._live()
        if not unit.plugged:
            return -1
        with unit.changed:
            unit.written.append(bytes(data))
            unit.changed.notify_all()
        return len(data)

    def send_feature_report(self, data: bytes | list[int]) -> int:
        unit = self._live()
        if not unit.plugged:
            return -1
        with unit.changed:
            unit.features.append(bytes(data))
            unit.changed.notify_all()
        return len(data)

    def get_report_descriptor(self) -> list[int]:
        return list(self._live().descriptor)

    def error(self) -> str:
        return "fake error"

    def close(self) -> None:
        self.unit = None


class FakeHidApi:
    """The module: ``enumerate(vid, pid)`` over plugged units and ``device()``."""

    def __init__(self, *units: FakeHidUnit) -> None:
        self.units = list(units)

    def enumerate(self, vendor_id: int = 0, product_id: int = 0) -> list[dict[str, Any]]:
        return [dict(u.info) for u in self.units if u.plugged
                and vendor_id in (0, u.info["vendor_id"]) and product_id in (0, u.info["product_id"])]

    def device(self) -> FakeHidDevice:
        return FakeHidDevice(self)

    def unplug(self, unit: FakeHidUnit) -> None:
        unit.plugged = False
        unit.reports.put([])  # wake a blocked read

    def replug(self, unit: FakeHidUnit) -> None:
        unit.reports = queue.Queue()
        unit.plugged = True
