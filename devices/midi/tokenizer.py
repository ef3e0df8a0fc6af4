"""The MIDI 1.0 byte tokenizer shared by every byte-stream path (rawmidi nodes, DIN MIDI on a UART).

A pure class fed bytes and a time, like ``SgiParser``, so it can be fuzzed alone. It follows the
MIDI 1.0 stream rules that simpler parsers get wrong (mido's included):

- running status: after a channel message, data bytes reuse the last channel status;
  system common messages (F1-F7) cancel it;
- real-time bytes (F8, FA, FB, FC, FE, FF) are messages of their own wherever they appear, also
  between a status and its data bytes or inside a SysEx, and disturb neither;
- SysEx ``F0 ... F7`` is kept up to ``sysex_cap`` bytes; a longer one is dropped whole (counted),
  and any status byte other than real-time ends an unterminated one (dropped, counted);
- undefined bytes (F4, F5, F9, FD, a stray F7) are dropped and counted without disturbing
  anything, and so are data bytes with no status to belong to.
"""

from __future__ import annotations

from devices.warn import WarningCounter

#: Number of data bytes after each channel status high nibble.
CHANNEL_DATA = {0x80: 2, 0x90: 2, 0xA0: 2, 0xB0: 2, 0xC0: 1, 0xD0: 1, 0xE0: 2}
#: System common: status -> data bytes (F0 and F7 handled apart).
COMMON_DATA = {0xF1: 1, 0xF2: 2, 0xF3: 1, 0xF6: 0}
REALTIME = frozenset({0xF8, 0xFA, 0xFB, 0xFC, 0xFE, 0xFF})
UNDEFINED = frozenset({0xF4, 0xF5, 0xF9, 0xFD})
SYSEX_CAP = 4096


def message_length(status: int) -> int:
    """Data bytes a message with this status carries (-1 for SysEx and undefined bytes)."""
    if status < 0xF0:
        return CHANNEL_DATA[status & 0xF0]
    if status in REALTIME:
        return 0
    return COMMON_DATA.get(status, -1)


class MidiTokenizer:
    """Bytes -> complete MIDI messages (tuples of ints, status first), in stream order.

    ``feed(data, t)`` returns ``[(message, t), ...]``; a message split across chunks is completed
    by a later chunk. Problems are counted in ``warnings`` (``garbage``, ``sysex``).
    """

    def __init__(self, source: str = "midi", sysex_cap: int = SYSEX_CAP,
                 warnings: WarningCounter | None = None) -> None:
        self.source = source
        self.sysex_cap = sysex_cap
        self.warnings = warnings or WarningCounter(source)
        self.reset()

    def reset(self) -> None:
        """Forget any message in progress and the running status (after a reconnect)."""
        self._running = 0          # running status (a channel status) or 0
        self._status = 0           # status of the message being collected, or 0
        self._need = 0             # data bytes still missing
        self._data: list[int] = []
        self._sysex: bytearray | None = None
        self._sysex_over = False

    def feed(self, data: bytes | bytearray | memoryview, t: float) -> list[tuple[tuple[int, ...], float]]:
        """Tokenize a chunk; returns every message it completes, each with time ``t``."""
        out: list[tuple[tuple[int, ...], float]] = []
        for b in bytes(data):
            if b >= 0xF8:
                if b in REALTIME:
                    out.append(((b,), t))
                else:
                    self._drop(f"undefined byte 0x{b:02x}")
                continue
            if b & 0x80:
                if b in UNDEFINED or (b == 0xF7 and self._sysex is None):
                    self._drop(f"undefined byte 0x{b:02x}" if b != 0xF7 else "end of SysEx without a start")
                else:
                    self._status_byte(b, t, out)
                continue
            # a data byte
            if self._sysex is not None:
                if len(self._sysex) < self.sysex_cap:
                    self._sysex.append(b)
                elif not self._sysex_over:
                    self._sysex_over = True
                    self.warnings.warn("sysex", f"SysEx longer than {self.sysex_cap} bytes dropped")
                continue
            if not self._status:
                if not self._running:
                    self._drop(f"data byte 0x{b:02x} without a status")
                    continue
                self._status, self._need, self._data = self._running, message_length(self._running), []
            self._data.append(b)
            self._need -= 1
            if self._need == 0:
                out.append(((self._status, *self._data), t))
                self._status, self._data = 0, []
        return out

    def _status_byte(self, b: int, t: float, out: list[tuple[tuple[int, ...], float]]) -> None:
        if self._sysex is not None:
            if b == 0xF7:
                if not self._sysex_over:
                    out.append(((0xF0, *self._sysex, 0xF7), t))
                self._sysex = None
                return
            self._sysex = None  # any other status ends it unfinished
            if not self._sysex_over:
                self.warnings.warn("sysex", "unterminated SysEx dropped")
        if self._status:
            self._drop(f"message 0x{self._status:02x} cut short by 0x{b:02x}")
            self._status, self._data = 0, []
        if b == 0xF0:
            self._running = 0
            self._sysex = bytearray()
            self._sysex_over = False
            return
        n = message_length(b)
        if b < 0xF0:
            self._running = b
        else:
            self._running = 0  # system common cancels running status
        if n == 0:
            out.append(((b,), t))
            return
        self._status, self._need, self._data = b, n, []

    def _drop(self, what: str) -> None:
        self.warnings.warn("garbage", f"{what} dropped")
