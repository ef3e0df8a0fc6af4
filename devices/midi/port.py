"""``midi://NAME[?profile=P&api=alsa|jack&channel=N]`` — a MIDI controller through python-rtmidi.

NAME is a case-insensitive substring of the port's client or port name (ALSA's ``20:0`` numbers
are ignored, so the name survives a replug). The API is always named: python-rtmidi does not fall
back from ALSA to JACK by itself, and neither do we (ALSA is the default on Linux). The input port
carries controls; the output port of the same name, when there is one, carries lights and rings.

On ALSA, python-rtmidi calls back on its own thread with whole messages; the callback only stamps
and queues them. On JACK, RtMidi receives in the JACK server's process thread, where a Python
callback would have to wait for the GIL and could make the whole graph miss its cycle; so the
reader thread takes RtMidi's queue every millisecond instead. Either way this device's reader
thread decodes, sends lights, and checks the port list every ``PORT_CHECK`` seconds (python-rtmidi
does not report a port that goes away). A vanished port is
``lost``; the base class reopens it every 0.2 s, and the reopen installs the callback again
(``close_port`` removes it) and restores the lights.
"""

from __future__ import annotations

import os
import queue
import re
import sys
import threading
import time
from collections.abc import Iterable
from typing import Any

from devices.errors import DeviceError, DeviceSpecError
from devices.events import ControlEvent
from devices.midi.common import MidiDevice, check_location
from devices.spec import DeviceSpec

#: Seconds between checks that the open port still exists.
PORT_CHECK = 0.25
#: Polling interval of a JACK input (JACK itself delivers once per period, 1.3-21 ms).
POLL_S = 0.001
#: After the MIDI API itself failed (no JACK server yet), wait this long before trying it again.
CLIENT_RETRY = 2.0
#: Our own client name; ports of clients named like this are never opened as a controller.
CLIENT = "facepuppet"
APIS = ("alsa", "jack")
_ALSA_NUMBERS = re.compile(r"\s+\d+:\d+$")


def _rtmidi() -> Any:
    try:
        import rtmidi
    except ImportError as err:
        raise DeviceError("midi:// needs python-rtmidi: pip install python-rtmidi") from err
    return rtmidi


def api_constant(api: str) -> int:
    rtmidi = _rtmidi()
    return {"alsa": rtmidi.API_LINUX_ALSA, "jack": rtmidi.API_UNIX_JACK,
            "coremidi": rtmidi.API_MACOSX_CORE, "winmm": rtmidi.API_WINDOWS_MM}[api]


def default_api() -> str:
    return {"darwin": "coremidi", "win32": "winmm"}.get(sys.platform, "alsa")


def clean_name(port: str) -> str:
    """A port name without ALSA's client:port numbers (they change from one plug-in to the next)."""
    return _ALSA_NUMBERS.sub("", port)


def jack_server_running() -> bool:
    """Whether a JACK server clients could talk to seems up, checked without starting one or
    letting libjack print its failure: jack2's socket for the server name, or a jack1 folder.
    Where neither layout applies (not Linux), assume it may be."""
    if not os.path.isdir("/dev/shm"):
        return True
    server = os.environ.get("JACK_DEFAULT_SERVER", "default")
    uid = os.getuid() if hasattr(os, "getuid") else 0
    sock = f"/dev/shm/jack_{server}_{uid}_0"
    return (os.path.exists(sock) and unix_socket_listened(sock)) or os.path.isdir(f"/dev/shm/jack-{uid}")


_ANSWERED: set[tuple[str, int, int]] = set()  # sockets that took a connection (path, inode, mtime)
#: the kernel's list of this network namespace's Unix sockets
PROC_NET_UNIX = "/proc/net/unix"


def unix_socket_listened(path: str) -> bool:
    """Whether a process listens on the Unix socket at ``path``: a JACK server killed (SIGKILL, a
    crash) leaves its socket file behind, and the file alone kept the server looking alive. Linux's
    /proc/net/unix lists the listening sockets (flag __SO_ACCEPTCON, 0x10000) by path; where it
    cannot be read, the file is taken at its word. It lists only this network namespace's sockets:
    a socket not listed is connected to once (refused: nobody listens; taken: a server in another
    namespace sharing /dev/shm, remembered for that socket file, never asked again)."""
    try:
        with open(PROC_NET_UNIX, encoding="utf-8", errors="replace") as f:
            next(f, None)  # the header
            for line in f:
                parts = line.split(None, 7)
                if len(parts) == 8 and parts[7].rstrip("\n") == path and int(parts[3], 16) & 0x10000:
                    return True
    except (OSError, ValueError):
        return True
    import socket

    try:
        st = os.stat(path)
    except OSError:
        return False
    key = (path, st.st_ino, st.st_mtime_ns)
    if key in _ANSWERED:
        return True
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as probe:
        probe.settimeout(1.0)
        try:
            probe.connect(path)
        except OSError:
            return False
    _ANSWERED.add(key)
    return True


def api_available(api: str) -> bool:
    """Cheap check before creating a client: a failed ALSA/JACK client prints to stderr."""
    if api == "alsa":
        return os.path.exists("/dev/snd/seq")
    if api == "jack":
        return jack_server_running()
    return True


def new_client(api: str, output: bool = False) -> Any:
    """A python-rtmidi MidiIn (or MidiOut) on ``api``; DeviceError naming what is missing."""
    rtmidi = _rtmidi()
    os.environ.setdefault("JACK_NO_START_SERVER", "1")  # never start a JACK server behind the user's back
    cls = rtmidi.MidiOut if output else rtmidi.MidiIn
    try:
        return cls(api_constant(api), name=CLIENT)
    except Exception as err:  # rtmidi raises its own SystemError / RuntimeError
        hint = {"alsa": "no ALSA sequencer (/dev/snd/seq); is this a JACK setup? use api=jack",
                "jack": "no JACK server running; start it (or use api=alsa)"}.get(api, str(err))
        raise DeviceError(f"cannot use the {api.upper()} MIDI API: {hint} ({err})") from err


def delete_client(client: Any) -> None:
    """Release a python-rtmidi client now (``del`` alone leaves it registered with the server)."""
    if client is None:
        return
    try:
        if client.is_port_open():
            client.close_port()
        client.delete()
    except Exception:
        pass


def foreign_ports(client: Any) -> list[str]:
    """The ports of a client's list that are not ours."""
    return [p for p in client.get_ports() if not p.lower().startswith(CLIENT)]


def find_port(ports: list[str], name: str, prefer: str = "") -> int | None:
    """Index of the first port whose cleaned name contains ``name`` (case-insensitive); among
    several, one that also contains ``prefer`` (the profile's port, e.g. an APC's Control port)."""
    low = name.lower()
    hits = [i for i, p in enumerate(ports) if low in clean_name(p).lower()]
    if prefer:
        better = [i for i in hits if prefer.lower() in ports[i].lower()]
        hits = better or hits
    return hits[0] if hits else None


class MidiPortDevice(MidiDevice):
    """A MIDI controller on an ALSA-sequencer or JACK port (CoreMIDI/WinMM where those run)."""

    scheme = "midi"
    FORM = "midi://NAME[?profile=P&api=alsa|jack&channel=N]"
    OPTIONS = frozenset({"profile", "api", "channel"})

    def __init__(self, spec: DeviceSpec, **options: Any) -> None:
        check_location(spec, self.FORM)
        api = spec.query.get("api", default_api()).lower()
        if api not in (*APIS, "coremidi", "winmm"):
            raise DeviceSpecError(f"{spec.text}: api={api!r}; expected api=alsa or api=jack ({self.FORM})")
        super().__init__(spec, **options)
        self.api = api
        self.name = spec.location
        self.description = f"{self.profile.title} on MIDI port {self.name!r} ({api.upper()})"
        self._in: Any = None
        self._out: Any = None
        self._port_name = ""
        self._out_name = ""
        self._inbox: queue.SimpleQueue[tuple[list[int], float] | None] = queue.SimpleQueue()
        self._next_check = 0.0
        self._retry_clients = 0.0
        self._started_at = float("inf")
        # JACK runs RtMidi's input in the server's process thread: a Python callback there would
        # wait for the GIL and make the whole JACK graph miss its cycle (an XRun drops that cycle's
        # MIDI, and other programs' audio); so on JACK the reader polls RtMidi's queue instead
        self._polled = self.api == "jack"
        self._woken = False
        self._server: object = None

    # ------------------------------------------------------------------ handle
    def _clients(self) -> tuple[Any, Any]:
        if self._in is None:
            now = time.monotonic()
            if now < self._retry_clients:  # the API failed a moment ago: do not hammer it (nor stderr)
                raise OSError(f"the {self.api.upper()} MIDI API is not available yet")
            if not api_available(self.api):
                self._retry_clients = now + CLIENT_RETRY
                hint = {"alsa": "no ALSA sequencer (/dev/snd/seq); is this a JACK setup? use api=jack",
                        "jack": f"no JACK server {os.environ.get('JACK_DEFAULT_SERVER', 'default')!r} running; "
                                "start it (or use api=alsa)"}[self.api]
                raise DeviceError(f"{self.spec}: {hint}")
            try:
                self._server = _server_identity(self.api)
                self._in = new_client(self.api)
            except DeviceError as err:
                self._retry_clients = now + CLIENT_RETRY
                raise DeviceError(f"{self.spec}: {err}") from err
            self._in.ignore_types(sysex=True, timing=True, active_sense=True)
        if self._out is None:
            self._out = new_client(self.api, output=True)
        return self._in, self._out

    def _open(self) -> None:
        self._close_handle()
        if self._in is not None and self._server != _server_identity(self.api):
            self._drop_clients()  # the JACK server was restarted: our clients talk to the old one
        try:
            inp, out = self._clients()
            ports = inp.get_ports()
        except DeviceError:
            raise
        except Exception as err:  # the server went away under a kept client: start afresh next time
            self._drop_clients()
            raise OSError(f"MIDI API {self.api} failed: {err}") from err
        mine = [p for p in ports if not p.lower().startswith(CLIENT)]
        idx = find_port(mine, self.name, self.profile.port)
        if idx is None:
            seen = ", ".join(repr(clean_name(p)) for p in mine) or "none"
            raise OSError(f"no MIDI input port matching {self.name!r} ({self.api.upper()}; ports: {seen})")
        self._port_name = mine[idx]
        while True:  # messages left from the last session must not leak into this one
            try:
                self._inbox.get_nowait()
            except queue.Empty:
                break
        inp.open_port(ports.index(self._port_name), f"{self.name} in")
        if self._polled:
            while inp.get_message() is not None:  # nothing from before this connection
                pass
        else:
            inp.set_callback(self._on_message)  # close_port removed the old one: install it every time
        self._out_name = ""
        self._open_output()
        self.decoder.reset()
        self.feedback.forget_sent()
        self._next_check = time.monotonic() + PORT_CHECK

    def _open_output(self) -> bool:
        """Open the box's input port (our output, for lights) if it is there; a box's ports may
        appear one after the other, so this is tried again at every port check until found."""
        outs = foreign_ports(self._out)
        j = find_port(outs, self.name, self.profile.port)
        if j is None:
            return False
        self._out.open_port(self._out.get_ports().index(outs[j]), f"{self.name} out")
        self._out_name = outs[j]
        return True

    def _close_handle(self) -> None:
        for client in (self._in, self._out):
            if client is not None:
                try:
                    if client.is_port_open():
                        client.close_port()
                except Exception:
                    pass

    def close(self) -> None:
        super().close()
        self._drop_clients()

    def _drop_clients(self) -> None:
        """Close our ALSA/JACK clients: a python-rtmidi object left to the garbage collector
        keeps its client (and its name) registered with the server."""
        clients, self._in, self._out = (self._in, self._out), None, None
        for client in clients:
            delete_client(client)

    def start(self) -> None:
        self._started_at = time.monotonic()
        super().start()

    def _wake(self) -> None:
        self._woken = True
        self._inbox.put(None)

    def _on_message(self, item: tuple[list[int], float], data: object = None) -> None:
        """python-rtmidi's thread: stamp and queue; nothing slow here."""
        self._inbox.put((item[0], time.monotonic()))

    # ------------------------------------------------------------------ reader thread
    def _read(self, timeout: float) -> Iterable[ControlEvent]:
        now = time.monotonic()
        if now >= self._next_check:
            self._check_port()
            self._next_check = now + PORT_CHECK
        wait = min(timeout, max(0.0, self._next_check - now))
        self._woken = False  # before sending: a light asked for after this point wakes the poll below
        due = self._send_lights(now)
        if due is not None:
            wait = min(wait, max(0.0, due - now))
        if self._polled:
            events = self._poll(wait)
            self._send_lights(time.monotonic())
            return events
        events: list[ControlEvent] = []
        try:
            item = self._inbox.get(timeout=wait) if wait > 0 else self._inbox.get_nowait()
        except queue.Empty:
            return events
        while True:  # everything that has arrived, in one batch
            if item is not None:  # a message queued before start() is read now, and stamped so
                events += self._decode(tuple(item[0]), max(item[1], self._started_at))
            try:
                item = self._inbox.get_nowait()
            except queue.Empty:
                break
        self._send_lights(time.monotonic())
        return events

    def _poll(self, wait: float) -> list[ControlEvent]:
        """JACK: take what RtMidi queued (its JACK thread never waits for Python), every POLL_S."""
        deadline = time.monotonic() + wait
        events: list[ControlEvent] = []
        get = self._in.get_message
        while True:
            item = get()
            while item is not None:
                events += self._decode(tuple(item[0]), max(time.monotonic(), self._started_at))
                item = get()
            if events or self._woken or time.monotonic() >= deadline:
                break
            time.sleep(POLL_S)
        return events

    def _check_port(self) -> None:
        if self.api == "jack" and _server_identity(self.api) != self._server:
            # a JACK client keeps its last copy of the server's graph when the server goes: the
            # box's port stayed listed after the server stopped (or crashed and came back), so the
            # device was never lost and never found the box on the new server
            raise OSError("the JACK server stopped or was restarted")
        ports = self._in.get_ports() if self._in is not None else []
        if self._port_name not in ports:
            raise OSError(f"MIDI port {clean_name(self._port_name)!r} went away")
        if not self._out_name and self._out is not None and self._open_output():
            self.feedback.forget_sent()
            self._restore_lights()  # the lights port came up after the controls port

    def _send_lights(self, now: float) -> float | None:
        msgs, nxt = self.feedback.due(now)
        if msgs and self._out_name:
            for m in msgs:
                self._out.send_message(list(m))
        return nxt


_ENUMERATORS: dict[str, tuple[object, Any]] = {}
_ENUM_LOCK = threading.Lock()
#: seconds a listing waits for the one before it
ENUM_WAIT = 5.0


def _server_identity(api: str) -> object:
    """What changes when the MIDI server is restarted: the JACK server's socket (a restarted
    server under the same name makes a new one); the ALSA sequencer lives as long as the kernel."""
    if api != "jack":
        return api
    server = os.environ.get("JACK_DEFAULT_SERVER", "default")
    uid = os.getuid() if hasattr(os, "getuid") else 0
    sock = f"/dev/shm/jack_{server}_{uid}_0"
    try:
        st = os.stat(sock)
    except OSError:
        return (server, None)
    if not unix_socket_listened(sock):  # killed: its socket file left behind, nobody listening
        return (server, None)
    return (server, st.st_ino, st.st_mtime_ns)


def list_ports(api: str) -> list[tuple[str, str]]:
    """(input port name, profile) for every controller port on ``api``; [] when the API is not
    available here. One client per API is kept for the process and asked again at every call:
    creating clients over and over makes the ALSA sequencer run out of memory for some users, and
    every new JACK client reorders the server's graph (a loaded server can drop that cycle's MIDI).
    The JACK client is replaced when the server it talks to was restarted."""
    if not api_available(api):
        return []
    from devices.midi.profile import profile_for_port

    ident = _server_identity(api)
    # a listing stuck in its server (a wedged JACK server blocks a client for good) holds the lock:
    # the next listing gives up rather than queue behind it
    if not _ENUM_LOCK.acquire(timeout=ENUM_WAIT):
        raise DeviceError(f"the {api.upper()} MIDI server did not answer: its ports are not listed")
    try:
        kept = _ENUMERATORS.get(api)
        client = kept[1] if kept is not None and kept[0] == ident else None
        if kept is not None and client is None:
            delete_client(_ENUMERATORS.pop(api)[1])
        try:
            if client is None:
                client = new_client(api)
                _ENUMERATORS[api] = (ident, client)
            return [(p, profile_for_port(p)) for p in foreign_ports(client)]
        except Exception:
            _ENUMERATORS.pop(api, None)
            delete_client(client)
            return []
    finally:
        _ENUM_LOCK.release()
