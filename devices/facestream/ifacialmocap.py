"""``ifacialmocap://127.0.0.1:49983[?phone=IP[:PORT]]`` — iFacialMocap (iOS): plain text over UDP, one
datagram per frame: ``name-value|name-value|...|=head#rx,ry,rz,px,py,pz|rightEye#...|leftEye#...|``
with weights 0..100, ``_L``/``_R`` suffixes and keys in any order (version 2 writes ``name&value``);
the head's and eyes' Euler angles (degrees) after ``#`` become the rotation controls.
The phone streams after a start request: with ``phone=IP`` the device sends it to that phone
(port 49983 unless given) when it opens and again while no frame arrives; the phone then needs this listener to
be reachable, so ``lan=1`` too."""

from __future__ import annotations

import math
import socket
import time
from typing import Any

from devices.errors import DeviceSpecError
from devices.events import ControlEvent
from devices.facestream import BlendshapeFrames, FaceStreamDevice, arkit_euler, arkit_name
from devices.spec import DeviceSpec
from devices.udp import is_loopback, split_host_port
from devices.warn import WarningCounter

START_REQUEST = b"iFacialMocap_sahuasouryya9218sauhuiayeta91555dy3719"
PHONE_PORT = 49983
MAX_FIELDS = 128
#: Seconds between start requests while no frame arrives.
REQUEST_EVERY = 2.0
POSES = {"head": "head", "lefteye": "leftEye", "righteye": "rightEye"}


class IFacialMocapParser:
    """iFacialMocap text frames -> blendshape events (weights / 100)."""

    def __init__(self, device: str, warnings: WarningCounter | None = None, mirror: bool = False) -> None:
        self.frames = BlendshapeFrames(device, warnings, mirror)

    def feed(self, data: bytes, t: float) -> list[ControlEvent]:
        try:
            text = data.decode("ascii")
        except UnicodeDecodeError:
            self.frames.warnings.warn("garbage", f"not iFacialMocap text: {data[:24]!r}")
            return []
        fields = text.split("|")
        if len(fields) > MAX_FIELDS:
            self.frames.warnings.warn("garbage", f"more than {MAX_FIELDS} fields in one frame")
            return []
        values: dict[str, float] = {}
        bad = 0
        for f in fields:
            f = f.strip()
            if "#" in f:  # head / eye poses (after "="): rx, ry, rz degrees (then the head's position)
                self._pose(f, values)
                continue
            if not f:
                continue
            sep = "&" if "&" in f else "-"
            name, _, num = f.rpartition(sep)
            key = arkit_name(name) if name else None
            try:
                v = float(num)
            except ValueError:
                bad += 1
                continue
            if key is None:
                self.frames.note_unknown(name[:64])
                continue
            if math.isfinite(v):
                values[key] = v / 100.0
            else:
                bad += 1
        if bad or not values:
            self.frames.warnings.warn("garbage", f"{bad or 'no'} readable name-value fields: {data[:24]!r}")
        return self.frames.emit(values, t, raw_scale=100.0) if values else []


    def _pose(self, field: str, values: dict[str, float]) -> None:
        name, _, nums = field.lstrip("=").partition("#")
        prefix = POSES.get(name.strip().lower())
        if prefix is None:
            self.frames.note_unknown(name[:64])
            return
        try:
            angles = [float(x) for x in nums.split(",")[:3]]
        except ValueError:
            angles = []
        if len(angles) == 3 and all(math.isfinite(a) for a in angles):
            values.update(arkit_euler(prefix, *angles))
        else:
            self.frames.warnings.warn("garbage", f"{name[:24]} pose is not three angles")


class IFacialMocapDevice(FaceStreamDevice):
    """iFacialMocap's stream (port 49983). Option ``phone=IP`` asks that phone to start sending."""

    scheme = "ifacialmocap"
    FORM = "ifacialmocap://127.0.0.1:49983[?phone=IP[:PORT]&lan=1&allow=ADDR,...&release=S&mirror=1]"
    OPTIONS = FaceStreamDevice.STREAM_OPTIONS | {"phone"}
    DEFAULT_PORT = PHONE_PORT
    WHAT = "iFacialMocap face tracking"
    PARSER = IFacialMocapParser

    def __init__(self, spec: DeviceSpec, **options: Any) -> None:
        super().__init__(spec, **options)
        self.phone: tuple[str, int] | None = None
        if spec.query.get("phone"):
            try:
                host, port = split_host_port(spec.query["phone"], PHONE_PORT, spec.text)
                socket.inet_pton(socket.AF_INET6 if ":" in host else socket.AF_INET, host)
            except (OSError, DeviceSpecError) as err:
                self.close()
                raise DeviceSpecError(f"{spec.text}: phone={spec.query['phone']!r} is not IP[:PORT]") from err
            if not self.lan and not is_loopback(host):
                self.close()
                raise DeviceSpecError(f"{spec.text}: the phone at {host} streams over the network, which needs a "
                                      "listener there too: add lan=1 (and allow=" + host + ")")
            self.phone = (host, port)
        self._requested = 0.0

    def _open(self) -> None:
        super()._open()
        self._request(time.monotonic())

    def _idle(self, t: float) -> list[ControlEvent]:
        if t - self._last_frame >= REQUEST_EVERY:
            self._request(t)
        return super()._idle(t)

    def _request(self, t: float) -> None:
        """Ask the phone to stream to us (it answers to the port the request came from)."""
        if self.phone is None or self._sock is None or t - self._requested < REQUEST_EVERY:
            return
        self._requested = t
        try:
            self._sock.sendto(START_REQUEST, self.phone)
        except OSError as err:
            self.warnings.warn("request", f"cannot ask {self.phone[0]} to start streaming: {err}")
