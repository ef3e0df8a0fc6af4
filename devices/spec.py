"""Device specs: one URL-like string names a device on the command line and in config files.

The form is ``scheme://location[?key=value&...]``. ``location`` is whatever the backend needs (a port
path, ``VID:PID``, ``interface/channel``, a script path); its meaning belongs to the backend, so this
module only splits the string and offers typed accessors that fail with the expected form.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from urllib.parse import parse_qsl, unquote

from devices.errors import DeviceSpecError


@dataclass(frozen=True)
class DeviceSpec:
    """A parsed spec. ``text`` is the original string, used verbatim as the device id in events."""

    text: str
    scheme: str
    location: str
    query: dict[str, str] = field(default_factory=dict)

    def check_options(self, allowed: set[str] | frozenset[str], form: str) -> None:
        """Reject unknown query keys, because a typo must not silently fall back to a default."""
        unknown = sorted(set(self.query) - set(allowed))
        if unknown:
            raise DeviceSpecError(
                f"{self.text}: unknown option {', '.join(unknown)!s}; expected {form}"
                + (f" with options {', '.join(sorted(allowed))}" if allowed else "")
            )

    def get_int(self, key: str, default: int, lo: int | None = None, hi: int | None = None) -> int:
        """An integer option, range-checked, so a bad value is reported with its name."""
        raw = self.query.get(key)
        if raw is None:
            return default
        try:
            value = int(raw, 0)
        except ValueError as err:
            raise DeviceSpecError(f"{self.text}: option {key}={raw!r} is not an integer") from err
        if (lo is not None and value < lo) or (hi is not None and value > hi):
            if hi is None:  # it said 'outside 0..None'
                raise DeviceSpecError(f"{self.text}: option {key}={value} must be {lo} or more")
            if lo is None:
                raise DeviceSpecError(f"{self.text}: option {key}={value} must be {hi} or less")
            raise DeviceSpecError(f"{self.text}: option {key}={value} is outside {lo}..{hi}")
        return value

    def get_float(self, key: str, default: float, lo: float | None = None) -> float:
        """A float option; rejects NaN and values below ``lo``."""
        raw = self.query.get(key)
        if raw is None:
            return default
        try:
            value = float(raw)
        except ValueError as err:
            raise DeviceSpecError(f"{self.text}: option {key}={raw!r} is not a number") from err
        if value != value or (lo is not None and value < lo):
            raise DeviceSpecError(f"{self.text}: option {key}={raw} must be a number >= {lo}")
        return value

    def get_bool(self, key: str, default: bool) -> bool:
        """A yes/no option (1/0, true/false, yes/no, on/off)."""
        raw = self.query.get(key)
        if raw is None:
            return default
        low = raw.lower()
        if low in ("1", "true", "yes", "on", ""):
            return True
        if low in ("0", "false", "no", "off"):
            return False
        raise DeviceSpecError(f"{self.text}: option {key}={raw!r} must be 1/0, true/false or yes/no")


def parse_spec(text: str) -> DeviceSpec:
    """Split ``scheme://location?query``; the scheme is lower-cased, the rest kept as written."""
    if not isinstance(text, str) or "://" not in text:
        raise DeviceSpecError(
            f"{text!r} is not a device spec; expected SCHEME://LOCATION[?OPTIONS], "
            "e.g. sgi:///dev/ttyUSB0, hid://077d:0410, keyboard://, mock://script.toml"
        )
    scheme, _, rest = text.partition("://")
    scheme = scheme.strip().lower()
    if not scheme.isidentifier():
        raise DeviceSpecError(f"{text!r}: bad scheme {scheme!r}")
    location, _, query_text = rest.partition("?")
    try:
        pairs = parse_qsl(query_text, keep_blank_values=True, strict_parsing=bool(query_text))
    except ValueError as err:
        raise DeviceSpecError(f"{text!r}: malformed options {query_text!r}; expected key=value&...") from err
    query: dict[str, str] = {}
    for key, value in pairs:
        if key in query:
            raise DeviceSpecError(f"{text!r}: option {key!r} given twice")
        query[key] = value
    return DeviceSpec(text=text, scheme=scheme, location=unquote(location), query=query)
