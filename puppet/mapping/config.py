"""The mapping file: TOML binding controls to channels through filter chains. This module parses
and checks the file's shape; the channel names are checked against the face in `engine`.
Every error is one line: `file:line:col: what was expected`."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from puppet.errors import ConfigError
from puppet.mapping.buttons import BUTTON_MODES
from puppet.mapping.filters import ENCODINGS
from puppet.mapping.locate import PathItem, locate
from safefile import BadFile, file_kind, load_toml, quote, read_text

COMBINE_RULES = ("max", "sum", "last")
MAX_NUMBER = 1e9  # any parameter beyond this is a typo (and an integer beyond a float's range is one)
INPUTS = ("absolute", "relative", "button")
ACTIONS = ("panic", "marker")
ENCODING_ALIASES = {"binary_offset": "offset64", "offset_64": "offset64", "2s_complement": "twos_complement",
                    "signed_bit": "sign_magnitude"}

# filter type -> {parameter: (kind, default)}; kind is "num", "bool", "pair", "points"
FILTER_PARAMS: dict[str, dict[str, tuple[str, Any]]] = {
    "range": {"from": ("pair", (0.0, 1.0)), "to": ("pair", (0.0, 1.0)), "clamp": ("bool", True)},
    "invert": {},
    "curve": {"gamma": ("num", None), "points": ("points", ())},
    "deadzone": {"width": ("num", 0.05), "center": ("num", 0.0)},
    "smooth": {"rise": ("num", 0.05), "fall": ("num", 0.05)},
    "one_euro": {"min_cutoff": ("num", 1.0), "beta": ("num", 0.0), "d_cutoff": ("num", 1.0)},
    "slew": {"rate": ("num", 4.0), "fall": ("num", None)},
}

BINDING_KEYS = {
    "control", "device", "target", "action", "input", "from", "to", "gain", "encoding", "bits",
    "counts_per_turn", "mode", "group", "attack", "hold", "release", "pickup", "pickup_window",
    "light", "filters", "label",
}


@dataclass
class FilterSpec:
    type: str
    params: dict[str, Any]
    path: tuple[PathItem, ...]


@dataclass
class BindingSpec:
    """One `[[binding]]`: which control (on which device) drives which target, and how."""

    index: int
    control: str
    target: str | None = None
    action: str | None = None
    device: str | None = None
    input: str | None = None
    src_range: tuple[float, float] | None = None
    dst_range: tuple[float, float] | None = None
    gain: float = 1.0
    encoding: str | None = None
    bits: int = 7
    counts_per_turn: float = 24.0
    mode: str = "momentary"
    group: str | None = None
    attack: float = 0.08
    hold: float = 0.0
    release: float = 0.15
    pickup: bool | None = None
    pickup_window: float = 0.04
    light: bool | None = None
    filters: list[FilterSpec] = field(default_factory=list)
    label: str = ""

    @property
    def path(self) -> tuple[PathItem, ...]:
        return ("binding", self.index)


@dataclass
class MappingSpec:
    """A parsed mapping file. `text`/`source` are kept so errors found later can be located and
    the mapping can be stored verbatim in a recording."""

    name: str
    bindings: list[BindingSpec]
    combine: dict[str, str]
    default_combine: str | None = None  # None: max, except eyes, age and head where the last one wins
    radio_allow_none: dict[str, bool] = field(default_factory=dict)
    source: str = "<mapping>"
    text: str = ""

    def error(self, path: Sequence[PathItem], message: str) -> ConfigError:
        """A ConfigError pointing at `path` in the file."""
        line, col = locate(self.text, path)
        return ConfigError(f"{self.source}:{line}:{col}: {message}")


class _Checker:
    def __init__(self, text: str, source: str) -> None:
        self.text, self.source = text, source

    def fail(self, path: Sequence[PathItem], message: str) -> ConfigError:
        line, col = locate(self.text, path)
        return ConfigError(f"{self.source}:{line}:{col}: {message}")

    def num(self, v: Any, path: Sequence[PathItem], *, positive: bool = False) -> float:
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise self.fail(path, f"expected a number for {path[-1]!s}, got {quote(v)}")
        if v != v or v in (float("inf"), float("-inf")):
            raise self.fail(path, f"expected a finite number for {path[-1]!s}")
        if abs(v) > MAX_NUMBER:
            raise self.fail(path, f"expected a number within +-{MAX_NUMBER:g} for {path[-1]!s}, got {quote(v)}")
        if positive and v < 0:
            raise self.fail(path, f"expected a number >= 0 for {path[-1]!s}, got {quote(v)}")
        return float(v)

    def pair(self, v: Any, path: Sequence[PathItem]) -> tuple[float, float]:
        if not isinstance(v, list) or len(v) != 2:
            raise self.fail(path, f"expected [low, high] for {path[-1]!s}, got {quote(v)}")
        a, b = (self.num(x, path) for x in v)
        if a == b:
            raise self.fail(path, f"expected two different numbers for {path[-1]!s}")
        return a, b

    def choice(self, v: Any, path: Sequence[PathItem], choices: Sequence[str]) -> str:
        if not isinstance(v, str) or v not in choices:
            raise self.fail(path, f"expected one of {', '.join(choices)} for {path[-1]!s}, got {quote(v)}")
        return v

    def string(self, v: Any, path: Sequence[PathItem]) -> str:
        if not isinstance(v, str) or not v:
            raise self.fail(path, f"expected a non-empty string for {path[-1]!s}, got {quote(v)}")
        return v

    def boolean(self, v: Any, path: Sequence[PathItem]) -> bool:
        if not isinstance(v, bool):
            raise self.fail(path, f"expected true or false for {path[-1]!s}, got {quote(v)}")
        return v

    def filter(self, v: Any, path: tuple[PathItem, ...]) -> FilterSpec:
        if isinstance(v, str):
            v = {"type": v}
        if not isinstance(v, dict) or "type" not in v:
            raise self.fail(path, "expected a filter like {type = \"smooth\", rise = 0.05}")
        ftype = self.choice(v["type"], path + ("type",), tuple(FILTER_PARAMS))
        allowed = FILTER_PARAMS[ftype]
        params: dict[str, Any] = {}
        for key, val in v.items():
            if key == "type":
                continue
            kp = path + (key,)
            if key not in allowed:
                names = ", ".join(allowed) or "no parameters"
                raise self.fail(kp, f"unknown parameter {quote(key)} for filter {ftype!r}; expected {names}")
            kind = allowed[key][0]
            if kind == "num":
                params[key] = self.num(val, kp, positive=ftype not in ("deadzone",))
            elif kind == "bool":
                params[key] = self.boolean(val, kp)
            elif kind == "pair":
                params[key] = self.pair(val, kp)
            else:
                if not isinstance(val, list) or len(val) < 2:
                    raise self.fail(kp, "expected points = [[x, y], [x, y], ...] (at least two)")
                pts = [self.point(pt, kp) for pt in val]
                if any(b[0] < a[0] for a, b in zip(pts, pts[1:])):
                    raise self.fail(kp, "expected curve points sorted by x")
                params[key] = tuple((float(a), float(b)) for a, b in pts)
        if ftype == "curve" and params.get("gamma") is None and not params.get("points"):
            raise self.fail(path, "expected gamma = <number> or points = [[x, y], ...] for a curve")
        for key, (_, default) in allowed.items():
            params.setdefault(key, default)
        return FilterSpec(ftype, params, path)

    def point(self, v: Any, path: Sequence[PathItem]) -> tuple[float, float]:
        if not isinstance(v, list) or len(v) != 2:
            raise self.fail(path, f"expected each curve point as [x, y], got {quote(v)}")
        return self.num(v[0], path), self.num(v[1], path)


def parse_mapping(text: str, source: str = "<mapping>") -> MappingSpec:
    """Parse and check a mapping file's text; raises ConfigError naming file:line:col."""
    try:
        data = load_toml(text, source, "mapping file")
    except BadFile as err:  # syntax (file:line:col), nesting thousands deep, an integer of 5000 digits
        raise ConfigError(str(err)) from err
    c = _Checker(text, source)
    known_top = {"version", "name", "binding", "combine", "groups", "device"}
    for key in data:
        if key not in known_top:
            raise c.fail((key,), f"unknown key {quote(key)}; expected one of {', '.join(sorted(known_top))}")
    if "version" in data and data["version"] != 1:
        raise c.fail(("version",), f"unsupported mapping version {quote(data['version'])}; expected 1")
    name = data.get("name", Path(source).stem)
    if not isinstance(name, str):
        raise c.fail(("name",), "expected a string for name")
    default_device = data.get("device")
    if default_device is not None:
        default_device = c.string(default_device, ("device",))

    combine: dict[str, str] = {}
    default_combine: str | None = None
    comb = data.get("combine", {})
    if not isinstance(comb, dict):
        raise c.fail(("combine",), "expected a [combine] table: channel = \"max\" | \"sum\" | \"last\"")
    for ch, rule in comb.items():
        r = c.choice(rule, ("combine", ch), COMBINE_RULES)
        if ch == "default":
            default_combine = r
        else:
            combine[ch] = r

    groups: dict[str, bool] = {}
    g = data.get("groups", {})
    if not isinstance(g, dict):
        raise c.fail(("groups",), "expected a [groups] table: name = { allow_none = true }")
    for gname, gval in g.items():
        if not isinstance(gval, dict):
            raise c.fail(("groups", gname), "expected { allow_none = true | false }")
        groups[gname] = c.boolean(gval.get("allow_none", True), ("groups", gname))

    raw_bindings = data.get("binding", [])
    if not isinstance(raw_bindings, list):
        raise c.fail(("binding",), "expected [[binding]] tables")
    bindings = [_binding(c, i, b, default_device) for i, b in enumerate(raw_bindings)]
    return MappingSpec(name, bindings, combine, default_combine, groups, source, text)


def _binding(c: _Checker, i: int, b: Any, default_device: str | None) -> BindingSpec:
    p: tuple[PathItem, ...] = ("binding", i)
    if not isinstance(b, dict):
        raise c.fail(p, "expected a [[binding]] table")
    for key in b:
        if key not in BINDING_KEYS:
            raise c.fail(p + (key,), f"unknown binding key {quote(key)}; expected one of {', '.join(sorted(BINDING_KEYS))}")
    if "control" not in b:
        raise c.fail(p, "expected control = \"<control name>\" in this binding")
    spec = BindingSpec(index=i, control=c.string(b["control"], p + ("control",)))
    if ("target" in b) == ("action" in b):
        raise c.fail(p, "expected exactly one of target = \"<channel|AUnn|expr:name>\" or action = \"panic\"|\"marker\"")
    if "target" in b:
        spec.target = c.string(b["target"], p + ("target",))
    else:
        spec.action = c.choice(b["action"], p + ("action",), ACTIONS)
    spec.device = c.string(b["device"], p + ("device",)) if "device" in b else default_device
    if "input" in b:
        spec.input = c.choice(b["input"], p + ("input",), INPUTS)
    if "from" in b:
        spec.src_range = c.pair(b["from"], p + ("from",))
    if "to" in b:
        spec.dst_range = c.pair(b["to"], p + ("to",))
    if "gain" in b:
        spec.gain = c.num(b["gain"], p + ("gain",))
    if "encoding" in b:
        enc = b["encoding"]
        enc = ENCODING_ALIASES.get(enc, enc) if isinstance(enc, str) else enc
        spec.encoding = c.choice(enc, p + ("encoding",), ENCODINGS)
    if "bits" in b:
        bits = c.num(b["bits"], p + ("bits",))
        if bits not in (7.0, 8.0, 14.0, 16.0):
            raise c.fail(p + ("bits",), "expected bits = 7, 8, 14 or 16")
        spec.bits = int(bits)
    if "counts_per_turn" in b:
        spec.counts_per_turn = c.num(b["counts_per_turn"], p + ("counts_per_turn",), positive=True) or 1.0
    if "mode" in b:
        spec.mode = c.choice(b["mode"], p + ("mode",), BUTTON_MODES)
    if "group" in b:
        spec.group = c.string(b["group"], p + ("group",))
        if "mode" not in b:
            spec.mode = "radio"
    if spec.mode == "radio" and spec.group is None:
        raise c.fail(p + ("mode",), "expected group = \"<name>\" for a radio button")
    for key in ("attack", "hold", "release", "pickup_window"):
        if key in b:
            setattr(spec, key, c.num(b[key], p + (key,), positive=True))
    if "pickup" in b:
        spec.pickup = c.boolean(b["pickup"], p + ("pickup",))
    if "light" in b:
        spec.light = c.boolean(b["light"], p + ("light",))
    if "label" in b:
        spec.label = c.string(b["label"], p + ("label",))
    fl = b.get("filters", [])
    if not isinstance(fl, list):
        raise c.fail(p + ("filters",), "expected filters = [ {type = \"smooth\", rise = 0.05}, ... ]")
    spec.filters = [c.filter(f, p + ("filters", k)) for k, f in enumerate(fl)]
    return spec


#: A mapping file is a few kilobytes; `puppet learn` reads it with the same bound.
MAX_MAP_BYTES = 16 * 1024 * 1024


def load_mapping(path: str | Path) -> MappingSpec:
    """Read and parse a mapping file; a missing or unreadable file is a one-line ConfigError."""
    p = Path(path)
    if file_kind(p) == "missing":
        raise ConfigError(f"{p}: mapping file not found")
    try:  # bounded: a wrong name (a take, /dev/zero) must not read gigabytes into memory
        text = read_text(p, "mapping file", MAX_MAP_BYTES)
    except BadFile as err:
        raise ConfigError(str(err)) from err
    return parse_mapping(text, str(p))
