"""What is plugged in: serial ports (optionally probed for SGI boxes and Firmata boards), HID
devices with a profile or a usable report descriptor, CAN channels, and the keyboard fallback."""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Any

log = logging.getLogger("devices")

#: Generic Desktop usages that are control boxes rather than keyboards and mice.
_PANEL_USAGES = {(0x01, 0x04): "joystick", (0x01, 0x05): "gamepad", (0x01, 0x08): "multi-axis controller"}
_NOT_PANELS = {(0x01, 0x02): "mouse", (0x01, 0x06): "keyboard"}


@dataclass(frozen=True, slots=True)
class DeviceInfo:
    """One candidate: the spec to open it, what it is, its kind and whether it can drive channels."""

    spec: str
    description: str
    kind: str
    usable: bool


#: seconds one family of devices may take to answer (probing serial ports takes longer); a family
#: that has not answered by then (a wedged JACK server or sound driver blocks its client for good) is
#: left out of this discovery with a warning, so a show never waits on it
FAMILY_TIMEOUT = 10.0
PROBE_TIMEOUT = 60.0


def discover(probe: bool = False, hid_api_module: Any = None, timeout: float | None = None) -> list[DeviceInfo]:
    """Everything found; each family is looked at independently (in its own thread, at most
    ``timeout`` seconds) so one failure or one driver that never answers hides nothing else."""
    import threading

    families = (("serial ports", lambda: serial_ports(probe)), ("HID devices", lambda: hid_devices(probe, hid_api_module)),
                ("CAN channels", can_channels), ("MIDI ports", midi_ports), ("audio inputs", audio_inputs))
    results: list[list[DeviceInfo] | None] = [None] * len(families)

    def look(i: int, family: Any) -> None:
        try:
            results[i] = list(family())
        except Exception as err:  # a broken driver stack must not hide the other families
            log.warning("device discovery: %s", err)
            results[i] = []

    threads = [threading.Thread(target=look, args=(i, f), name=f"discover-{name}", daemon=True)
               for i, (name, f) in enumerate(families)]
    for t in threads:
        t.start()
    limit = timeout if timeout is not None else (PROBE_TIMEOUT if probe else FAMILY_TIMEOUT)
    import time

    deadline = time.monotonic() + limit
    found: list[DeviceInfo] = []
    for (name, _), t, i in zip(families, threads, range(len(families)), strict=True):
        t.join(max(0.0, deadline - time.monotonic()))
        got = results[i]
        if got is None:  # still waiting on its driver: the thread is left to finish on its own
            log.warning("device discovery: the %s did not answer within %g s; left out this time", name, limit)
            continue
        found += got
    found.append(DeviceInfo("keyboard://", "keyboard of the application window (always available)", "keyboard", True))
    return found


#: seconds a probed port is listened to for text-protocol lines (an Arduino reset by the opening
#: of its port says its hello ~1.6 s later)
TEXT_LISTEN = 3.0
#: seconds after an SGI box's ack in which nothing but acks may arrive, probing
ACK_QUIET = 0.15


def probe_serial_port(path: str) -> str | None:
    """``"sgi"`` or ``"firmata"`` when the box on ``path`` answers like one, ``"serial"`` when it
    speaks the text protocol within TEXT_LISTEN seconds at 115200 baud, else None (silent).
    Writes a reset byte at 9600 baud and a version query at 57600 baud: opt-in only."""
    import time
    from devices.errors import DeviceError
    from devices.firmata import FirmataDevice
    from devices.sgi import RESET, SgiDevice
    from devices.spec import parse_spec

    class QuickSgi(SgiDevice):
        RESET_TRIES = 2
        RESET_WAIT = 0.3

        def _wait_for_ack(self, seconds: float, settle: bool = False) -> bool:
            """The box's ack is 0x20, an ASCII space: a port that talks text (a text-protocol box, a
            console, a GPS) was taken for an SGI box by the first space in its stream. Probing, the
            reply must be acks alone, with nothing else until a short while after."""
            if settle:
                return super()._wait_for_ack(seconds, settle)
            deadline = time.monotonic() + seconds
            acked = False
            while (left := deadline - time.monotonic()) > 0:
                data, _t = self.read_raw(max(0.001, left))
                if data.strip(bytes([RESET])):
                    return False
                if data and not acked:
                    acked = True
                    deadline = min(deadline, time.monotonic() + ACK_QUIET)
            return acked

    for scheme, cls, query in (("sgi", QuickSgi, ""), ("firmata", FirmataDevice, "?boot_wait=2.5")):
        dev = cls(parse_spec(f"{scheme}://{path}{query}"))
        try:
            dev.open()
            return scheme
        except DeviceError:
            continue
        finally:
            dev.close()
    return "serial" if speaks_text_protocol(path) else None


def speaks_text_protocol(path: str, seconds: float = TEXT_LISTEN) -> bool:
    """Whether a line of the text protocol (a hello, a button, dial or axis line) arrives on
    ``path`` at 115200 baud within ``seconds``; garbage, comments and silence are not enough."""
    import time

    import serial

    from devices.textserial import TextParser

    parser = TextParser(path)
    try:
        port = serial.Serial(path, 115200, timeout=0.1)
    except (OSError, ValueError, serial.SerialException):
        return False
    try:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            data = port.read(256)
            if data and (parser.feed(data, 0.0) or parser.hello):
                return True
    except (OSError, serial.SerialException):
        return False
    finally:
        port.close()
    return False


def serial_ports(probe: bool = False) -> list[DeviceInfo]:
    """Serial ports with USB VID:PID and description; probed ones get their real scheme."""
    from serial.tools import list_ports

    out = []
    ports = sorted(list_ports.comports(), key=lambda p: p.device)
    schemes: dict[str, str | None] = {}
    if probe and ports:
        # each port takes up to ~6 s (the SGI reset, the Firmata board's boot, the text box's
        # hello): probed one after the other, a few ports outlasted the discovery's minute
        from concurrent.futures import ThreadPoolExecutor

        with ThreadPoolExecutor(max_workers=min(16, len(ports)), thread_name_prefix="probe") as pool:
            schemes = dict(zip((p.device for p in ports), pool.map(probe_serial_port, (p.device for p in ports))))
    for port in ports:
        usb = f"USB {port.vid:04x}:{port.pid:04x} " if port.vid is not None else ""
        desc = f"{usb}{port.description or port.device}"
        if port.serial_number:
            desc += f" (serial {port.serial_number})"
        if probe:
            scheme = schemes.get(port.device)
            if scheme == "sgi":
                out.append(DeviceInfo(f"sgi://{port.device}", f"SGI dial-and-button box; {desc}", "serial", True))
                continue
            if scheme == "firmata":
                out.append(DeviceInfo(f"firmata://{port.device}", f"Firmata board; {desc}", "serial", True))
                continue
            if scheme == "serial":
                out.append(DeviceInfo(f"serial://{port.device}", f"text-protocol box; {desc}", "serial", True))
                continue
            # silent: no answer to either probe and no text-protocol line; before, every probed port
            # was marked usable, so `--probe --json` offered a modem or a console as a control box
            desc += ("; silent: no SGI/Firmata answer and no text-protocol line at 115200 baud (a text box "
                     "that speaks only when touched: try puppet monitor serial://PORT and move a control)")
            out.append(DeviceInfo(f"serial://{port.device}", desc, "serial", False))
            continue
        out.append(DeviceInfo(f"serial://{port.device}", desc, "serial", port.vid is not None))
    return out


def hid_devices(probe: bool = False, api: Any = None) -> list[DeviceInfo]:
    """HID devices that have a profile, declare a joystick/gamepad usage, or (with ``probe``) whose
    report descriptor yields buttons or axes."""
    from devices.hid.profiles import known_name

    if api is None:
        from devices.hid.transport import hid_api

        api = hid_api()
    entries = api.enumerate(0, 0)
    counts: dict[tuple[int, int], int] = {}
    for e in entries:
        counts[(e["vendor_id"], e["product_id"])] = counts.get((e["vendor_id"], e["product_id"]), 0) + 1
    out, seen = [], set()
    for e in entries:
        if e["path"] in seen:
            continue
        seen.add(e["path"])
        vid, pid = e["vendor_id"], e["product_id"]
        spec = f"hid://{vid:04x}:{pid:04x}"
        if counts[(vid, pid)] > 1 and e.get("serial_number"):
            spec += f"?serial={e['serial_number']}"
        product = (e.get("product_string") or "").strip() or "HID device"
        name = known_name(vid, pid)
        usage = (e.get("usage_page", 0), e.get("usage", 0))
        if name:
            out.append(DeviceInfo(spec, f"{name} (built-in profile)", "hid", True))
        elif usage in _PANEL_USAGES:
            out.append(DeviceInfo(spec, f"{product} ({_PANEL_USAGES[usage]}, from its descriptor)", "hid", True))
        elif usage in _NOT_PANELS:
            out.append(DeviceInfo(spec, f"{product} ({_NOT_PANELS[usage]})", "hid", False))
        elif probe:
            ok, why = _descriptor_usable(api, e)
            out.append(DeviceInfo(spec, f"{product} ({why})", "hid", ok))
        else:
            out.append(DeviceInfo(spec, f"{product} (use --probe to read its report descriptor)", "hid", False))
    return out


def _descriptor_usable(api: Any, entry: dict[str, Any]) -> tuple[bool, str]:
    from devices.hid.descriptor import GenericDecoder, ReportDescriptor
    from devices.hid.transport import HidHandle

    try:
        handle = HidHandle.open_path(api, entry["path"])
    except Exception as err:
        return False, f"cannot open: {err} (permissions? see docs/devices.md)"
    try:
        dec = GenericDecoder("probe", ReportDescriptor.parse(handle.report_descriptor()))
    except Exception as err:
        return False, f"unreadable report descriptor: {err}"
    finally:
        handle.close()
    if not dec.usable():
        return False, "no buttons or axes in its report descriptor"
    kinds = sorted({c.kind for c in dec.controls})
    return True, f"{len(dec.controls)} controls ({', '.join(kinds)}) from its report descriptor"


def can_channels() -> list[DeviceInfo]:
    """SocketCAN interfaces that exist, plus the channel python-can's configuration names."""
    import can

    configs: list[dict[str, Any]] = []
    try:
        configs += can.detect_available_configs(interfaces=["socketcan"])
    except Exception as err:
        log.debug("socketcan detection: %s", err)
    try:
        cfg = can.util.load_config()
        if cfg.get("interface") and cfg.get("channel") is not None:
            configs.append(cfg)
    except Exception as err:
        log.debug("python-can configuration: %s", err)
    out, seen = [], set()
    for cfg in configs:
        key = (cfg["interface"], str(cfg["channel"]))
        if key not in seen:
            seen.add(key)
            out.append(DeviceInfo(f"can://{key[0]}/{key[1]}?dbc=PANEL.dbc",
                                  f"CAN channel {key[1]} ({key[0]}); name your panel's DBC file", "can", True))
    return out


def midi_ports() -> list[DeviceInfo]:
    """MIDI input ports on the ALSA sequencer and on a running JACK server (devices.midi)."""
    from devices.midi.discover import midi_ports as _midi_ports

    return _midi_ports()


def audio_inputs() -> list[DeviceInfo]:
    """Audio inputs (ALSA, and JACK when a server runs) a voice can drive the mouth from
    (devices.audio); `puppet live` uses one only when named with --device."""
    from devices.audio.device import audio_inputs as _audio_inputs

    return [DeviceInfo(spec, desc, "audio", True) for spec, desc in _audio_inputs()]
