"""Native channel curves as CSV: one row per output frame, every channel in our own units, floats
in repr so nothing is rounded away. Keeps what ARKit cannot express (AU11, AU13, age...)."""

from __future__ import annotations

import csv
from pathlib import Path
from typing import IO

import numpy as np

from puppet.errors import ConfigError


class ChannelCsvWriter:
    """Columns: frame, time (s), tick, then one column per channel."""

    def __init__(self, path: str | Path, channel_names: list[str]) -> None:
        try:
            self._fh: IO[str] | None = open(path, "w", newline="", encoding="utf-8")
        except OSError as err:
            raise ConfigError(f"{path}: cannot write the CSV: {err.strerror}") from err
        self._csv = csv.writer(self._fh)
        self._csv.writerow(["frame", "time", "tick", *channel_names])

    def add(self, frame: int, time: float, tick: int, values: np.ndarray) -> None:
        self._csv.writerow([frame, repr(float(time)), tick, *(repr(float(v)) for v in values)])

    def close(self) -> None:
        if self._fh is not None:
            self._fh.close()
            self._fh = None
