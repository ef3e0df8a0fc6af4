"""The shipped default maps (puppet/maps/*.toml) and which one a device gets, so every supported
box is useful without writing a mapping file."""

from __future__ import annotations

import re
from dataclasses import replace
from importlib import resources
from pathlib import Path

from puppet.mapping.config import BindingSpec, MappingSpec, parse_mapping

#: USB vendor:product (or vendor alone) -> map name, for hid:// specs.
HID_MAPS = {
    "077d:0410": "powermate",
    "0b33:0020": "shuttlexpress",
    "0b33:0030": "shuttlexpress",
    "05f3": "xkeys",
}
SCHEME_MAPS = {
    "sgi": "sgi", "keyboard": "keyboard", "firmata": "firmata", "serial": "textbox", "can": "can_panel",
    "powermate": "powermate", "shuttle": "shuttlexpress", "xkeys": "xkeys", "gamepad": "gamepad",
    "audio": "voice",
}
KIND_WORDS = (("powermate", "powermate"), ("shuttle", "shuttlexpress"), ("x-keys", "xkeys"),
              ("xkeys", "xkeys"), ("gamepad", "gamepad"), ("joystick", "gamepad"), ("sgi", "sgi"))


def map_names() -> list[str]:
    return sorted(p.name[:-5] for p in resources.files("puppet.maps").iterdir() if p.name.endswith(".toml"))


def map_text(name: str) -> str:
    return (resources.files("puppet.maps") / f"{name}.toml").read_text(encoding="utf-8")


def load_default_map(name: str) -> MappingSpec:
    return parse_mapping(map_text(name), f"puppet/maps/{name}.toml")


#: Network listeners: OSC by profile, face-tracking streams by their blendshapes.
NET_MAPS = {"facecap": "arkit", "vmc": "arkit", "ifacialmocap": "arkit", "livelink": "arkit"}


def osc_map_name(scheme: str, spec: str) -> str | None:
    """`osc_<profile>` for an osc:// spec, `arkit` for a face-tracking stream, else None."""
    if scheme == "osc":
        m = re.search(r"[?&]profile=([a-z]+)", spec.lower())
        return f"osc_{m.group(1) if m else 'generic'}"
    return NET_MAPS.get(scheme)


def default_map_name(spec: str, kind: str = "") -> str | None:
    """The default map for a device spec (and its discovered kind/description), or None."""
    scheme, _, rest = spec.partition("://")
    scheme = scheme.lower()
    if scheme == "osc" or scheme in NET_MAPS:
        return osc_map_name(scheme, spec)
    if scheme == "mock":
        m = re.search(r"impersonate=([a-z]+)", spec)
        box = m.group(1) if m else "sgi"
        return {"shuttlepro": "shuttlexpress", "serial": "textbox"}.get(box, box) if box in (
            "sgi", "powermate", "shuttlexpress", "shuttlepro", "serial", "keyboard", "firmata") else "sgi"
    if scheme in ("midi", "rawmidi"):
        return _midi_map(rest, kind)
    if scheme == "hid":
        ids = rest.split("?", 1)[0].lower()
        for key, name in HID_MAPS.items():
            if ids.startswith(key):
                return name
    text = f"{scheme} {kind}".lower()
    for word, name in KIND_WORDS:
        if word in text:
            return name
    return SCHEME_MAPS.get(scheme)


def _midi_map(rest: str, kind: str) -> str | None:
    """A MIDI controller's map is named after its profile (the spec's, else the one its port name
    or description selects); a controller without a profile has none (bind it with learn)."""
    from devices.midi.profile import profile_for_port

    m = re.search(r"[?&]profile=([A-Za-z0-9_]+)", rest)
    profile = m.group(1).lower() if m else profile_for_port(f"{rest.split('?', 1)[0]} {kind}")
    return profile if profile != "generic" and profile in map_names() else None


def for_device(spec: MappingSpec, device: str) -> list[BindingSpec]:
    """The map's bindings restricted to one device (so two boxes of a kind stay independent)."""
    return [replace(b, device=device, group=f"{device}|{b.group}" if b.group else None) for b in spec.bindings]


def merge(specs: list[tuple[MappingSpec, str | None]], name: str = "default maps") -> MappingSpec:
    """One MappingSpec from several (map, device) pairs; each map's bindings are tied to its device
    when one is given. Radio groups stay per device. Check each map against the face before merging
    (errors are located in the merged text only approximately)."""
    bindings: list[BindingSpec] = []
    combine: dict[str, str] = {}
    groups: dict[str, bool] = {}
    texts = []
    default_combine = None
    for spec, device in specs:
        bs = for_device(spec, device) if device else list(spec.bindings)
        bindings += bs
        combine.update(spec.combine)
        default_combine = default_combine or spec.default_combine
        for g, allow in spec.radio_allow_none.items():
            groups[f"{device}|{g}" if device else g] = allow
        texts.append(f"# --- {spec.source}" + (f" for {device}" if device else "") + "\n" + spec.text)
    out = [replace(b, index=i) for i, b in enumerate(bindings)]
    return MappingSpec(name, out, combine, default_combine, groups, name, "\n".join(texts))


def shipped_map_path(name: str) -> Path:
    return Path(str(resources.files("puppet.maps") / f"{name}.toml"))
