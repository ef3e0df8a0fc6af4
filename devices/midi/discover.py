"""MIDI controllers that are plugged in: the input ports of the ALSA sequencer and of a running JACK
server, each with the profile its name selects. A port without a profile is listed as not usable
by `puppet live` on its own (it could be a synthesizer), but `puppet learn --device SPEC` binds it."""

from __future__ import annotations

from devices.discovery import DeviceInfo, log
from devices.errors import DeviceError
from devices.midi.port import list_ports

#: Ports that are never a controller.
SKIP = ("midi through", "system:")


def midi_ports(apis: tuple[str, ...] = ("alsa", "jack")) -> list[DeviceInfo]:
    from devices.midi.profile import load_profile

    out: list[DeviceInfo] = []
    seen: set[str] = set()
    for api in apis:
        try:
            ports = list_ports(api)
        except DeviceError as err:  # one API's server stuck: the other's ports are still listed
            log.warning("device discovery: %s", err)
            continue
        for port, profile in ports:
            if port.lower().startswith(SKIP):
                continue
            client = port.split(":", 1)[0].strip() or port
            spec = f"midi://{client}?profile={profile}&api={api}"
            if spec in seen:
                continue  # a box with several ports (APC mini mk2): the profile picks the one to use
            seen.add(spec)
            prof = load_profile(profile)
            if profile == "generic":
                out.append(DeviceInfo(spec, f"MIDI port {port!r} ({api.upper()}); no profile: bind it with "
                                      "`puppet learn --device SPEC`", "midi", False))
            else:
                note = f"; {prof.note}" if prof.note else ""
                out.append(DeviceInfo(spec, f"{prof.title} on MIDI port {port!r} ({api.upper()}){note}", "midi", True))
    return out
