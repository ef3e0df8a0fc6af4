"""A self-pipe that lets a reader blocked in ``select`` on a file or a socket return at once when
the device is closed: backends that wait in ``select`` add its read end to what they wait on."""

from __future__ import annotations

import os


class WakePipe:
    """Non-blocking pipe: ``wake()`` from any thread, ``drain()`` in the reader, ``close()`` once."""

    def __init__(self) -> None:
        self._r, self._w = os.pipe()
        os.set_blocking(self._r, False)
        os.set_blocking(self._w, False)

    def fileno(self) -> int:
        """The read end, for ``select`` (-1 once closed)."""
        return self._r

    def wake(self) -> None:
        try:
            os.write(self._w, b"x")
        except OSError:  # closed, or already full of wake-ups: either way the reader will return
            pass

    def drain(self) -> None:
        try:
            os.read(self._r, 4096)
        except OSError:
            pass

    def close(self) -> None:
        for fd in (self._r, self._w):
            try:
                os.close(fd)
            except OSError:
                pass
        self._r = self._w = -1


class SelectWaking:
    """Mixin for a device whose ``_read`` waits in ``select`` on ``self._waker`` among its handles:
    ``_wake`` (close is waiting) writes to the pipe, and closing the device closes the pipe."""

    _waker: WakePipe

    def close(self) -> None:
        super().close()  # type: ignore[misc]
        self._waker.close()

    def _wake(self) -> None:
        self._waker.wake()
