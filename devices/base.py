"""The Device base class: lifecycle, listeners and the one reader thread with reconnection.

Backends fill in four small hooks (``_open``, ``_read``, ``_close_handle``, ``_set_light``); the
base owns everything a live show depends on: a reader thread that never dies from an exception,
lost/connected status events, reopening within ``reconnect_interval`` after a device comes back,
and an idempotent ``close``.
"""

from __future__ import annotations

import logging
import os
import threading
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any, ClassVar

from devices.errors import DeviceError
from devices.events import ControlEvent, EventKind, StatusEvent
from devices.spec import DeviceSpec
from devices.warn import WarningCounter

log = logging.getLogger("devices")

Event = ControlEvent | StatusEvent
Listener = Callable[[Event], None]


@dataclass(frozen=True, slots=True)
class ControlInfo:
    """A declared control: its name in events, its kind, the range of ``value`` and whether it has
    a light ``set_light`` can drive. For dials the range bounds one event's change in turns."""

    name: str
    kind: EventKind
    lo: float = 0.0
    hi: float = 1.0
    has_light: bool = False


class Device:
    """Base class of every backend. Construct through ``devices.open_device``."""

    scheme: ClassVar[str] = ""
    #: The accepted query options and the spec form, shown when a spec is wrong.
    OPTIONS: ClassVar[frozenset[str]] = frozenset()
    FORM: ClassVar[str] = "SCHEME://LOCATION"
    #: Seconds between reopen attempts while lost (the hot-plug promise is "within 1 s").
    reconnect_interval: ClassVar[float] = 0.2
    #: Upper bound of one blocking read; reads return as soon as data arrives.
    read_timeout: ClassVar[float] = 0.1

    def __init__(self, spec: DeviceSpec, **options: Any) -> None:
        spec.check_options(self.OPTIONS, self.FORM)
        self.spec: str = spec.text
        self.parsed = spec
        self.description: str = spec.text
        self.controls: list[ControlInfo] = []
        self.warnings = WarningCounter(spec.text)
        self._listeners: tuple[Listener, ...] = ()
        self._listener_lock = threading.Lock()
        self._connected = False
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._closed = False
        self._lights: dict[str, float] = {}
        #: the last status told to listeners (None: none yet); `_status` keeps them alternating
        self.reported: str | None = None
        #: why the last open failed ("" after a success), for the show's status lines
        self.last_error = ""
        self._status_lock = threading.Lock()

    # ----------------------------------------------------------------- public API
    @property
    def connected(self) -> bool:
        """True while the hardware is open and answering."""
        return self._connected

    def address_exists(self) -> bool:
        """True when the hardware's address exists even though opening it failed just now (a
        port that is there but does not answer yet): the show may start and retry it."""
        return False

    @property
    def drops(self) -> int | None:
        """Input lost before this program could read it (a network listener's overflowed receive
        buffer); None where a device cannot lose input that way."""
        return None

    @property
    def exhausted(self) -> bool:
        """True when a finite source (a mock script) has delivered everything it ever will."""
        return False

    def control(self, name: str) -> ControlInfo | None:
        """The declared control called ``name``, if any."""
        for info in self.controls:
            if info.name == name:
                return info
        return None

    def add_listener(self, fn: Listener) -> None:
        """Call ``fn(event)`` from the reader thread for every event; it must be quick."""
        with self._listener_lock:
            self._listeners = (*self._listeners, fn)

    def remove_listener(self, fn: Listener) -> None:
        """Stop calling ``fn``; unknown listeners are ignored."""
        with self._listener_lock:
            self._listeners = tuple(f for f in self._listeners if f is not fn)

    def open(self) -> None:
        """Open the hardware now; raises DeviceError naming the spec when it is not there."""
        try:
            self._open()
        except DeviceError as err:
            self._safe_close_handle()
            self.last_error = str(err)
            raise
        except Exception as err:
            self._safe_close_handle()
            self.last_error = str(err)
            raise DeviceError(f"{self.spec}: cannot open: {err}") from err
        self._connected = True
        self.last_error = ""

    def start(self) -> None:
        """Start the reader thread (once). It reports ``connected`` first when the device is open."""
        if self._closed:
            raise DeviceError(f"{self.spec}: device is closed")
        if self._thread is not None:
            return
        self._thread = threading.Thread(target=self._run, name=f"device {self.spec}", daemon=True)
        self._thread.start()

    def close(self) -> None:
        """Stop the reader thread and release the hardware; safe to call any number of times."""
        if self._closed:
            return
        self._closed = True
        self._stop.set()
        self._wake()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout=3.0)
        self._safe_close_handle()
        self._connected = False

    def set_light(self, control: str, on: bool | float) -> None:
        """Light a button (True/False or a 0..1 level); a silent no-op where there is no light."""
        level = max(0.0, min(1.0, float(on)))
        info = self.control(control)
        if info is None or not info.has_light:
            return
        self._lights[control] = level
        if self._connected:
            try:
                self._set_light(control, level)
            except Exception as err:  # a failing light must never reach the live loop
                self.warnings.warn("light", f"cannot set light {control}: {err}")

    def __enter__(self) -> Device:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"<{type(self).__name__} {self.spec} connected={self._connected}>"

    # ----------------------------------------------------------------- hooks
    def _open(self) -> None:
        """Open the hardware handle and initialise the box; raise OSError/DeviceError if absent."""
        raise NotImplementedError

    def _read(self, timeout: float) -> Iterable[ControlEvent]:
        """Wait up to ``timeout`` for input and return the decoded events; raise OSError when the
        device is gone. Must return promptly after ``_wake``."""
        raise NotImplementedError

    def _close_handle(self) -> None:
        """Release the hardware handle; called after loss and on close, possibly twice."""

    def _set_light(self, control: str, level: float) -> None:
        """Drive one light; only called for controls declared with ``has_light``."""

    @property
    def closing(self) -> bool:
        """True once close() was called; long handshakes check it to give up early."""
        return self._stop.is_set()

    def _wake(self) -> None:
        """Make a blocked ``_read`` return early (close is waiting)."""

    def _restore_lights(self) -> None:
        """Re-send remembered light states after a reconnect, so a toggle keeps glowing."""
        for name, level in list(self._lights.items()):
            try:
                self._set_light(name, level)
            except Exception as err:
                self.warnings.warn("light", f"cannot restore light {name}: {err}")

    # ----------------------------------------------------------------- reader thread
    def emit(self, event: Event) -> None:
        """Hand one event to every listener; a failing listener is logged, never fatal."""
        for fn in self._listeners:
            try:
                fn(event)
            except Exception as err:
                self.warnings.warn("listener", f"listener {fn!r} failed: {err!r}")

    def _now(self) -> float:
        """The clock of status events; a scripted device replaces it with its script clock."""
        return time.monotonic()

    def _status(self, status: str, detail: str = "", t: float | None = None) -> None:
        """Tell the listeners the device came or went. What they hear strictly alternates
        (connected, lost, connected...): a repeated ``lost`` is not told again, and a
        ``connected`` after a ``connected`` (a reopen whose loss went unreported) is preceded by
        the ``lost`` it implies, so a recording or a HUD never reads two states in a row."""
        with self._status_lock:
            t = self._now() if t is None else t
            if status == self.reported:
                if status != "connected":
                    return
                self.emit(StatusEvent(self.spec, "lost", t, f"lost before: {detail or 'reconnected'}"))
            self.reported = status
            self.emit(StatusEvent(self.spec, status, t, detail))  # type: ignore[arg-type]

    def _safe_close_handle(self) -> None:
        try:
            self._close_handle()
        except Exception as err:
            log.debug("%s: closing handle failed: %s", self.spec, err)

    def _lose(self, err: BaseException) -> None:
        """The device went away: drop the stale handle and tell the listeners once."""
        self._connected = False
        self._safe_close_handle()
        self.warnings.warn("lost", f"lost ({err}); reconnecting")  # rate-limited: a flapping bus
        self._status("lost", str(err))

    def _try_reopen(self) -> bool:
        try:
            self._open()
        except Exception as err:
            self._safe_close_handle()
            self.last_error = str(err)
            log.debug("%s: reopen failed: %s", self.spec, err)
            return False
        if self._stop.is_set():  # close() came while we were opening: do not leak the handle
            self._safe_close_handle()
            return False
        self._connected = True
        self._restore_lights()
        if self.reported == "lost":  # said as the loss was: a show without a window hears it is back
            self.warnings.warn("back", "connected again")
        self._status("connected", "reopened" if self.reported else "opened")
        return True

    def _raise_priority(self) -> None:
        """With ``PUPPET_REALTIME_DEVICES=1``, run this reader thread under SCHED_FIFO so a busy
        machine cannot delay a control event; needs CAP_SYS_NICE (or an rtprio limit), and is
        skipped with one log line when not permitted."""
        if os.environ.get("PUPPET_REALTIME_DEVICES") != "1" or not hasattr(os, "sched_setscheduler"):
            return
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(10))  # 0 = this thread on Linux
        except OSError as err:
            log.info("%s: real-time priority not permitted (%s)", self.spec, err)

    def _run(self) -> None:
        self._raise_priority()
        if self._connected:
            self._restore_lights()
            self._status("connected")
        opened = time.monotonic()
        while not self._stop.is_set():
            if not self._connected:
                if not self._try_reopen():
                    self._stop.wait(self.reconnect_interval)
                else:
                    opened = time.monotonic()
                continue
            try:
                events = list(self._read(self.read_timeout))
            except Exception as err:  # OSError, SerialException, CanError, parser bugs alike
                if self._stop.is_set():
                    break
                self._lose(err)
                if time.monotonic() - opened < self.reconnect_interval:
                    # lost as soon as it opened (a node that opens and then reads end of file, a
                    # box failing right after its handshake): reopening at once spun the thread,
                    # 52,000 lost/connected pairs a second into the show and its recording
                    self._stop.wait(self.reconnect_interval)
                continue
            for event in events:
                self.emit(event)
