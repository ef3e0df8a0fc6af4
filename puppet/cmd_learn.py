"""`puppet learn`: touch a control, name a channel, and the binding is written into a mapping file.

Prompts go to stdout and answers come from stdin, one line each, so a session can be scripted:
    printf 'jaw\\nexpr:happiness\\ntoggle\\n' | puppet learn --device mock://take.toml --map my.toml
"""

from __future__ import annotations

import argparse
import math
import re
import sys
import time
from typing import Any, TextIO

#: An absolute control must move this much (of its range) to count as "touched": pots jitter.
AXIS_TOUCH = 0.05
MODES = ("momentary", "toggle", "trigger")
ENCODINGS = ("twos_complement", "offset64", "sign_magnitude")
#: A MIDI control reported under its generic name (no profile names it): maybe a relative encoder.
GENERIC_CC = re.compile(r"ch\d+\.cc\d+$")
#: An absolute pot never sends one value three times running; a relative encoder turned one way does.
REL_RUN = 3


def relative_guess(raw: int) -> str | None:
    """The likely encoding of a relative encoder repeating ``raw``: 1-15 up or 113-127 down in
    two's complement, 49-63 down or 65-79 up around 64 (offset64; sign-magnitude 65 = -1 looks
    the same, so the user is asked)."""
    if 1 <= raw <= 15 or 113 <= raw <= 127:
        return "twos_complement"
    if 49 <= raw <= 79 and raw != 64:
        return "offset64"
    return None


def register(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = subparsers.add_parser(
        "learn",
        help="bind controls by touching them: writes bindings into a mapping file",
        description="Touch a control, then type the target (channel, pair, AU12, expr:happiness; ? lists "
        "them; empty skips; q quits). The binding is added to --map with tomlkit, keeping comments.",
    )
    p.add_argument("--device", action="append", default=[], metavar="SPEC",
                   help="device spec (default: every box found)")
    p.add_argument("--map", metavar="FILE", help="mapping file to add bindings to (created if missing)")
    p.add_argument("--profile", metavar="FILE",
                   help="with --device audio://NAME: record your own vowels into this voice profile instead "
                   "(then use audio://NAME?profile=FILE); see docs/audio.md")
    p.add_argument("--timeout", type=float, default=None, metavar="S",
                   help="give up when no control is touched for S seconds")
    p.set_defaults(func=run)


class _Touch:
    """Turns an event stream into 'touched' controls: dials on any turn, buttons on press, axes
    once they moved AXIS_TOUCH from where they were first seen."""

    def __init__(self) -> None:
        self.first: dict[tuple[str, str], float] = {}
        self.runs: dict[tuple[str, str], list[object]] = {}
        self.encoding: str | None = None  # set when the touched control looks like a relative encoder

    def touched(self, ev: Any) -> bool:
        self.encoding = None
        if ev.kind == "dial":
            return ev.value != 0
        if ev.kind in ("button", "key"):
            return ev.value > 0.5
        key = (ev.device, ev.control)
        if GENERIC_CC.match(ev.control) and isinstance(ev.raw, int):
            run = self.runs.setdefault(key, [])
            run.append(ev.raw)
            del run[:-REL_RUN]
            if len(run) == REL_RUN and len(set(run)) == 1 and relative_guess(ev.raw):
                self.encoding = relative_guess(ev.raw)
                return True
        start = self.first.setdefault(key, ev.value)
        return abs(ev.value - start) >= AXIS_TOUCH


def _ask(prompt: str, stdin: TextIO) -> str | None:
    print(prompt, end="", flush=True)
    line = stdin.readline()
    if not line:
        return None
    return line.strip()


def run(args: argparse.Namespace, stdin: TextIO | None = None) -> int:
    import devices
    from puppet.cmd_live import _open_devices
    from puppet.errors import ChannelError, PuppetError
    from puppet.live import load_face
    from puppet.mapping.learn import learn_binding

    stdin = stdin or sys.stdin
    timeout = getattr(args, "timeout", None)
    if timeout is not None and not (timeout > 0 and math.isfinite(timeout)):
        # nan or -1 gave up at once ('learned 0 binding(s)'), before any control could be touched
        raise PuppetError(f"--timeout must be a positive number of seconds, got {timeout}")
    if getattr(args, "profile", None):
        if len(args.device) != 1 or not args.device[0].lower().startswith("audio:"):
            raise PuppetError("--profile learns a voice: give exactly one --device audio://NAME")
        from puppet.voice_learn import learn_voice

        return learn_voice(args.device[0], args.profile, stdin)
    if not args.map:
        raise PuppetError("give --map FILE to learn bindings into (or --profile FILE with an audio:// device)")
    from puppet.mapping.learn import check_learn_file

    check_learn_file(args.map)  # before the performer touches anything
    face = load_face()
    devs = _open_devices(list(args.device), lambda m: print(f"puppet: {m}", file=sys.stderr))
    devs = [d for d in devs if not d.spec.startswith("keyboard")]
    if not devs:
        raise PuppetError("no control box to learn from: plug one in or pass --device SPEC "
                          "(the keyboard map is edited by hand: see docs/live.md)")
    queue = devices.EventQueue()
    try:
        for d in devs:
            d.add_listener(queue)
            d.start()
        print(f"learning into {args.map} from {', '.join(d.spec for d in devs)}; touch a control (Ctrl+C ends)")
        touch = _Touch()
        learned = 0
        while True:
            ev = _next_touch(queue, touch, args.timeout)
            if ev is None:
                print("no control touched: done")
                break
            encoding = touch.encoding
            kind = "dial" if encoding else ev.kind
            print(f"touched {ev.control} ({'relative encoder' if encoding else ev.kind}) on {ev.device}")
            while True:
                answer = _ask("target (channel, AU12, expr:NAME; ? lists, empty skips, q quits): ", stdin)
                if answer is None or answer == "q":
                    print(f"learned {learned} binding(s)")
                    return 0
                if answer == "?":
                    print("  " + " ".join(face.vocab.all_targets()))
                    continue
                if answer == "":
                    break
                try:
                    face.vocab.resolve(answer)
                except ChannelError as err:
                    print(f"  {err}")
                    continue
                mode, settings = None, None
                if ev.kind in ("button", "key"):
                    m = _ask(f"button mode ({'/'.join(MODES)}; empty = momentary): ", stdin)
                    mode = m if m in MODES else None
                if encoding:
                    e = _ask(f"encoding ({'/'.join(ENCODINGS)}; empty = {encoding}): ", stdin)
                    settings = {"input": "relative", "encoding": e if e in ENCODINGS else encoding}
                how = learn_binding(args.map, ev.control, ev.device, answer, kind, mode, settings)
                learned += 1
                print(f"{how}: {ev.control} -> {answer}")
                break
            _settle(queue, ev)
    finally:
        for d in devs:
            d.close()
    print(f"learned {learned} binding(s)")
    return 0


def _next_touch(queue: Any, touch: _Touch, timeout: float | None) -> Any:
    deadline = None if timeout is None else time.monotonic() + timeout
    while deadline is None or time.monotonic() < deadline:
        ev = queue.get(timeout=0.1)
        if ev is None or not hasattr(ev, "control"):
            continue
        if touch.touched(ev):
            return ev
    return None


def _settle(queue: Any, learned: Any) -> None:
    """Drop the rest of the gesture that was just learned (the dial still turning, the release)."""
    quiet_until = time.monotonic() + 0.3
    keep = []
    while time.monotonic() < quiet_until:
        ev = queue.get(timeout=0.05)
        if ev is None:
            continue
        if getattr(ev, "control", None) == learned.control and ev.device == learned.device:
            quiet_until = time.monotonic() + 0.3
            continue
        keep.append(ev)
    for ev in keep:
        queue.put(ev)
