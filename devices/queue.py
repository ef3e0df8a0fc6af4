"""EventQueue: the hand-over point between reader threads and the live loop."""

from __future__ import annotations

import queue
import threading

from devices.events import ControlEvent, StatusEvent

Event = ControlEvent | StatusEvent


class EventQueue:
    """A device listener that is a thread-safe FIFO.

    Reader threads call it (or ``put``); the live loop calls ``drain()`` once per tick and never
    blocks. ``get(timeout)`` is for tools and tests that want to wait for the next event.
    ``maxsize`` bounds memory if nobody drains; the oldest events are then dropped and counted,
    because a stalled consumer must never stall a reader thread.
    """

    def __init__(self, maxsize: int = 100_000) -> None:
        self._q: queue.Queue[Event] = queue.Queue(maxsize=maxsize)
        self.dropped = 0
        self._arrived = threading.Event()

    def put(self, event: Event) -> None:
        """Append one event; never blocks."""
        while True:
            try:
                self._q.put_nowait(event)
                self._arrived.set()
                return
            except queue.Full:
                try:
                    self._q.get_nowait()
                    self.dropped += 1
                except queue.Empty:
                    pass

    __call__ = put

    def drain(self) -> list[Event]:
        """Everything queued so far, oldest first; an empty list when nothing happened."""
        self._arrived.clear()  # before taking: an event put meanwhile sets it again
        out: list[Event] = []
        while True:
            try:
                out.append(self._q.get_nowait())
            except queue.Empty:
                return out

    def wait_arrival(self, timeout: float) -> bool:
        """Wait up to `timeout` seconds for an event put since the last `drain`; True when one was
        (the live loop wakes on it instead of waiting for its next tick boundary)."""
        return self._arrived.wait(max(0.0, timeout))

    def get(self, timeout: float | None = None) -> Event | None:
        """The next event, waiting up to ``timeout`` seconds; None when none arrived."""
        try:
            return self._q.get(timeout=timeout)
        except queue.Empty:
            return None

    def __len__(self) -> int:
        return self._q.qsize()
