"""Where the samples come from: ALSA (and PulseAudio) through python-sounddevice over PortAudio, and
JACK through JACK-Client.

JACK does not go through PortAudio: Debian's PortAudio 19.6 aborts the whole process (an assertion in
its JACK host API's Terminate) once the JACK server it saw has gone, and its blocking reads over JACK
corrupt memory; a show must survive a server restart. So for ``api=jack`` our own JACK client opens
an input port and connects it to the named client's output port, and PortAudio is not even loaded.
PortAudio is loaded only for ALSA/PulseAudio, and is shut down again (when that is safe) once no
stream of this process uses it.

A source calls ``deliver(samples, frame)`` from the audio system's own thread with one channel's block
(float32) and, where the audio system counts them (JACK), the frame of its first sample; it must
only copy it."""

from __future__ import annotations

import atexit
import logging
import os
import re
import threading
from collections.abc import Callable
from typing import Any

import numpy as np

from devices.errors import DeviceError

log = logging.getLogger("devices")
HOSTAPI_NAMES = {"alsa": "ALSA", "pulse": "PulseAudio"}
CLIENT = "facepuppet"
#: Inputs that are never a voice: our own clients and PortAudio's.
OWN = ("facepuppet", "portaudio")
Deliver = Callable[[np.ndarray, "int | None"], None]

_PA_LOCK = threading.RLock()
_pa_users = 0
_pa_jack_at_init: object = None


def jack_running() -> bool:
    from devices.midi.port import jack_server_running

    return jack_server_running()


def _jack_identity() -> object:
    from devices.midi.port import _server_identity

    return _server_identity("jack") if jack_running() else None


# ------------------------------------------------------------------------------------ PortAudio
def sounddevice() -> Any:
    """python-sounddevice with PortAudio initialised (call `release_portaudio` when done)."""
    global _pa_users, _pa_jack_at_init
    os.environ.setdefault("JACK_NO_START_SERVER", "1")  # never start a JACK server behind the user's back
    with _PA_LOCK:
        try:
            import sounddevice as sd
        except (ImportError, OSError) as err:
            raise DeviceError("audio:// on ALSA needs python-sounddevice and the PortAudio library "
                              f"(pip install sounddevice; Debian: apt install libportaudio2): {err}") from err
        if not getattr(sounddevice, "_hooked", False):
            atexit.unregister(sd._exit_handler)  # its Terminate may abort (see the module docstring)
            sounddevice._hooked = True  # type: ignore[attr-defined]
            _pa_jack_at_init = _jack_identity()
        if _pa_users == 0 and sd._initialized == 0:
            sd._initialize()
            _pa_jack_at_init = _jack_identity()
        _pa_users += 1
        return sd


def release_portaudio() -> None:
    """One user of `sounddevice()` is done; the last one shuts PortAudio down, unless a JACK server
    it connected to has gone since (then it is left as it is: terminating would abort)."""
    global _pa_users
    import sounddevice as sd

    with _PA_LOCK:
        _pa_users = max(0, _pa_users - 1)
        if _pa_users or sd._initialized == 0:
            return
        if _pa_jack_at_init is not None and _jack_identity() != _pa_jack_at_init:
            return
        while sd._initialized:
            sd._terminate()


def portaudio_inputs(api: str) -> list[tuple[int, str, int]]:
    """(PortAudio index, name, input channels) of every input on one host API."""
    sd = sounddevice()
    try:
        out = []
        for info in sd.query_hostapis():
            if info["name"] != HOSTAPI_NAMES[api]:
                continue
            for i in info["devices"]:
                d = sd.query_devices(i)
                if d["max_input_channels"] > 0 and not d["name"].lower().startswith(OWN):
                    out.append((i, d["name"], int(d["max_input_channels"])))
        return out
    finally:
        release_portaudio()


class PortAudioSource:
    """An ALSA (or PulseAudio) input through python-sounddevice."""

    def __init__(self, api: str, name: str, channel: int) -> None:
        self.api, self.wanted, self.channel = api, name, channel
        self.name, self.rate, self.latency = "", 48000.0, 0.0
        self._stream: Any = None
        self._sd: Any = None

    def _find(self) -> tuple[int, str, int]:
        found = portaudio_inputs(self.api) if self.api != "pulse" or self._native_pulse() else []
        low = self.wanted.lower()
        hits = [x for x in found if low in x[1].lower()]
        if hits:
            return hits[0]
        if self.api == "pulse":
            alsa = [x for x in portaudio_inputs("alsa") if x[1].lower() == "pulse"]
            if not alsa:
                raise DeviceError("no PulseAudio here (neither PortAudio's PulseAudio host API nor ALSA's pulse "
                                  "device); use api=alsa or api=jack")
            os.environ["PULSE_SOURCE"] = self.wanted  # ALSA's pulse device records from this source
            return alsa[0]
        if not found and not os.path.isdir("/proc/asound"):
            raise DeviceError("no ALSA sound card here (no /proc/asound); is this a JACK setup? use api=jack")
        seen = ", ".join(repr(x[1]) for x in found) or "none"
        raise OSError(f"no audio input matching {self.wanted!r} ({self.api.upper()}; inputs: {seen})")

    def _native_pulse(self) -> bool:
        sd = sounddevice()
        try:
            return any(h["name"] == "PulseAudio" for h in sd.query_hostapis())
        finally:
            release_portaudio()

    def open(self, deliver: Deliver) -> None:
        index, name, channels = self._find()
        if self.channel >= channels:
            raise DeviceError(f"input {name!r} has {channels} channel(s); channel={self.channel + 1} does not exist")
        sd = sounddevice()
        ch = self.channel

        def callback(indata: Any, frames: int, time_info: Any, status: Any) -> None:
            deliver(indata[:, ch], None)

        try:
            rate = float(sd.query_devices(index)["default_samplerate"] or 48000)
            stream = sd.InputStream(device=index, channels=ch + 1, samplerate=rate, dtype="float32",
                                    latency="low", callback=callback)
            stream.start()
        except Exception as err:  # PortAudioError: busy, gone, bad rate
            release_portaudio()
            raise OSError(f"cannot open audio input {name!r}: {err}") from err
        self._sd, self._stream = sd, stream
        self.name, self.rate = name, float(stream.samplerate)
        self.latency = float(stream.latency) if isinstance(stream.latency, float) else 0.0

    def present(self) -> bool:
        return self._stream is not None and bool(self._stream.active)

    def close(self) -> None:
        stream, self._stream = self._stream, None
        if stream is None:
            return
        try:
            stream.abort()
            stream.close()
        except Exception:
            pass
        release_portaudio()


# ------------------------------------------------------------------------------------ JACK
def _jack() -> Any:
    os.environ.setdefault("JACK_NO_START_SERVER", "1")
    try:
        import jack
    except (ImportError, OSError) as err:
        raise DeviceError(f"audio:// on JACK needs JACK-Client and libjack (pip install JACK-Client): {err}") from err
    if not getattr(_jack, "_quiet", False):  # libjack's chatter (a closing client, a gone server) goes to the log
        jack.set_error_function(lambda msg: log.debug("jack: %s", msg))
        jack.set_info_function(lambda msg: log.debug("jack: %s", msg))
        _jack._quiet = True  # type: ignore[attr-defined]
    return jack


def jack_sources(client: Any) -> dict[str, list[str]]:
    """Client name -> its audio output ports (the voices a JACK graph offers), ours left out."""
    out: dict[str, list[str]] = {}
    for port in client.get_ports(is_audio=True, is_output=True):
        owner = port.name.split(":", 1)[0]
        if owner.lower().startswith(OWN):
            continue
        out.setdefault(owner, []).append(port.name)
    return out


def jack_inputs() -> list[tuple[str, int]]:
    """(client name, output port count) of every JACK client with audio outputs; [] without a server."""
    if not jack_running():
        return []
    jack = _jack()
    try:
        client = jack.Client(f"{CLIENT}-list", no_start_server=True)
    except Exception:
        return []
    try:
        return [(k, len(v)) for k, v in jack_sources(client).items()]
    finally:
        try:
            client.close()
        except Exception:
            pass


class JackSource:
    """A JACK client's output port, connected to an input port of our own JACK client."""

    def __init__(self, name: str, channel: int) -> None:
        self.wanted, self.channel = name, channel
        self.name, self.rate, self.latency = "", 48000.0, 0.0
        self._client: Any = None
        self._source_port = ""
        self._dead = False

    def open(self, deliver: Deliver) -> None:
        if not jack_running():
            server = os.environ.get("JACK_DEFAULT_SERVER", "default")
            raise DeviceError(f"no JACK server {server!r} running; start it (or use api=alsa)")
        jack = _jack()
        try:
            client = jack.Client(CLIENT, no_start_server=True)
        except Exception as err:
            raise OSError(f"cannot talk to the JACK server: {err}") from err
        try:
            sources = jack_sources(client)
            low = self.wanted.lower()
            hits = [k for k in sources if low in k.lower()]
            if not hits:
                seen = ", ".join(repr(k) for k in sources) or "none"
                raise OSError(f"no audio input matching {self.wanted!r} (JACK; inputs: {seen})")
            ports = sources[hits[0]]
            if self.channel >= len(ports):
                raise DeviceError(f"input {hits[0]!r} has {len(ports)} channel(s); "
                                  f"channel={self.channel + 1} does not exist")
            inport = client.inports.register("voice_in")
            self._dead = False

            @client.set_process_callback
            def process(frames: int) -> None:
                deliver(inport.get_array(), client.last_frame_time)

            @client.set_shutdown_callback
            def shutdown(status: Any, reason: str) -> None:
                self._dead = True

            client.activate()
            client.connect(ports[self.channel], inport)
            try:  # what JACK says the sound took to reach the port (a capture card's period, else 0)
                self.latency = inport.get_latency_range(jack.CAPTURE)[1] / client.samplerate
            except Exception:
                self.latency = 0.0
        except BaseException:
            _close_jack(client)
            raise
        self._client, self._source_port = client, ports[self.channel]
        self.name, self.rate = hits[0], float(client.samplerate)

    def present(self) -> bool:
        client = self._client
        if client is None or self._dead:
            return False
        try:
            return bool(client.get_ports(f"^{re.escape(self._source_port)}$", is_output=True))
        except Exception:
            return False

    def close(self) -> None:
        client, self._client = self._client, None
        if client is not None:
            _close_jack(client)


def _close_jack(client: Any) -> None:
    try:
        client.deactivate()
    except Exception:
        pass
    try:
        client.close()  # a server that went away makes this fail: the client is gone anyway
    except Exception:
        pass


def make_source(api: str, name: str, channel: int) -> PortAudioSource | JackSource:
    return JackSource(name, channel) if api == "jack" else PortAudioSource(api, name, channel)


def audio_inputs(apis: tuple[str, ...] = ("alsa", "jack")) -> list[tuple[str, str]]:
    """(spec, description) of every audio input, for `puppet devices`."""
    out: list[tuple[str, str]] = []
    if "alsa" in apis and os.path.isdir("/proc/asound"):
        for _, name, ch in portaudio_inputs("alsa"):
            if name.lower() in ("default", "sysdefault", "dmix", "dsnoop"):
                continue
            out.append((f"audio://{name}?api=alsa", _describe(name, "ALSA", ch)))
    if "jack" in apis:
        for name, ch in jack_inputs():
            out.append((f"audio://{name}?api=jack", _describe(name, "JACK", ch)))
    return out


def _describe(name: str, api: str, ch: int) -> str:
    return f"audio input {name!r} ({api}, {ch} channel{'s' if ch != 1 else ''}); a voice drives the mouth"
