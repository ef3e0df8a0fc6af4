"""Counted, rate-limited warnings for bad input.

A box spewing garbage at 9600 baud must not flood the log or slow the reader thread, yet the user
must learn that something is wrong: every problem is counted by kind, and logged at most once per
``interval`` per kind with the number suppressed since.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import Counter

log = logging.getLogger("devices")


class WarningCounter:
    """Counts problems by kind (``garbage``, ``range``, ``decode``...) and logs them sparingly."""

    def __init__(self, source: str, interval: float = 1.0, logger: logging.Logger = log) -> None:
        self.source = source
        self.interval = interval
        self.counts: Counter[str] = Counter()
        self._logger = logger
        self._last: dict[str, float] = {}
        self._suppressed: Counter[str] = Counter()
        self._lock = threading.Lock()

    def warn(self, kind: str, message: str) -> None:
        """Record one problem of ``kind``; log it unless one of that kind was logged recently."""
        now = time.monotonic()
        with self._lock:
            self.counts[kind] += 1
            last = self._last.get(kind)
            if last is not None and now - last < self.interval:
                self._suppressed[kind] += 1
                return
            self._last[kind] = now
            skipped = self._suppressed.pop(kind, 0)
        extra = f" ({skipped} more suppressed)" if skipped else ""
        self._logger.warning("%s: %s%s", self.source, message, extra)

    def total(self) -> int:
        """All problems counted so far."""
        with self._lock:
            return sum(self.counts.values())
