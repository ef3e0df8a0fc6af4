"""`puppet live`: perform with the control boxes plugged in (or the keyboard), optionally recording."""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any


def register(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = subparsers.add_parser(
        "live",
        help="perform live: control boxes (or the keyboard) drive the face",
        description="Perform live. With no --device, every supported box found is used; with none, the "
        "keyboard of the face window; with neither a box nor a display, the built-in demo (--demo). "
        "ESC eases the face back to neutral, M drops a marker. See docs/live.md.",
    )
    p.add_argument("--device", action="append", default=[], metavar="SPEC",
                   help="a device spec (sgi:///dev/ttyUSB0, mock://script.toml, ...); repeatable")
    p.add_argument("--map", metavar="FILE", help="mapping file (default: the shipped map of each device)")
    p.add_argument("--rig", metavar="PATH", help="rig file (default: the built-in face)")
    p.add_argument("--face", metavar="SPEC", default=None,
                   help="the face: ict (the scanned head), ict?identity=SEED, procedural or a saved identity's NAME")
    p.add_argument("--record", metavar="FILE", help="record the session to FILE (JSON Lines)")
    p.add_argument("--performer", metavar="NAME", help="who performs (kept in the take and the take library)")
    p.add_argument("--tag", action="append", default=[], metavar="TAG",
                   help="tag the recording in the take library; repeatable")
    p.add_argument("--library", metavar="PATH", help="the take library the recording is added to (default: your "
                   "data folder; PUPPET_LIBRARY=off for none)")
    p.add_argument("--headless", action="store_true", help="no window: for scripted and recorded runs")
    p.add_argument("--duration", type=float, metavar="S", help="stop cleanly after S seconds")
    p.add_argument("--fullscreen", action="store_true", help="fullscreen window")
    p.add_argument("--pipelined", action="store_true",
                   help="window: make each frame's posing while the frame before is still being drawn (more "
                   "frames a second on a software rasterizer, each shown a frame later)")
    p.add_argument("--demo", action="store_true",
                   help="perform the built-in demo (about 20 s): in the window when there is a display, "
                   "else headless into a recording, an MP4 and a PNG in the current folder")
    p.add_argument("--panel", type=int, metavar="PORT",
                   help="serve the performer's page on this port (default: served on 8765 or the next free port)")
    p.add_argument("--no-panel", action="store_true", help="do not serve the performer's page")
    p.add_argument("--panel-lan", action="store_true",
                   help="serve the page to the LAN (all interfaces), behind a random token in the printed URL")
    p.add_argument("--panel-role", action="append", default=[], metavar="NAME=PATTERNS",
                   help="a page role limited to some channels, e.g. mouth=jaw,orbicularis_oris,AU26 "
                   "(open the page with ?role=mouth); repeatable. See docs/panel.md")
    p.add_argument("--supervise", action="store_true",
                   help="restart the show within a second if it crashes, continuing the same take "
                   "(a new segment of the recording) with the face's last channel values; see docs/live.md")
    p.add_argument("--resume", action="store_true",
                   help="continue the --record FILE if it exists (a new segment) instead of starting it "
                   "again (what --supervise and the systemd unit in docs/live.md do after a crash)")
    p.add_argument("--tick-rate", type=float, choices=(60.0, 120.0, 240.0), default=None, metavar="HZ",
                   help="simulation ticks a second: 60, 120 or 240 (default headless: the fastest the face's "
                   "measured step affords, 120 for the scanned head; 60 in a window and on a script's clock); "
                   "frames are still drawn at the display's rate, a faster tick shortens the wait of an event "
                   "for the simulation; the take records it (see docs/live.md)")
    p.add_argument("--realtime", action=argparse.BooleanOptionalAction, default=None,
                   help="headless: run the live loop and the devices' reader threads under real-time scheduling "
                   "(SCHED_FIFO) so a busy machine delays no tick; needs CAP_SYS_NICE or an rtprio limit "
                   "(see docs/live.md, Latency). Default: used wherever it is permitted, quietly; --realtime "
                   "says so when it is not; --no-realtime keeps the ordinary scheduling")
    p.add_argument("--standby", action="store_true", help=argparse.SUPPRESS)  # --supervise's spare
    p.set_defaults(func=run)


def _open_devices(specs: list[str], warn: Any) -> list[Any]:
    """The devices named on the command line, or every usable box found (not the keyboard)."""
    import devices

    opened = []
    if specs:
        twice = sorted({s for s in specs if specs.count(s) > 1})
        if twice:  # the second opened the same port again: 'in use by another program' (this show)
            from puppet.errors import PuppetError

            raise PuppetError(f"--device {twice[0]} is given twice; name each device once")
        for spec in specs:
            # a bad spec or a port that is not there is the user's error (one line, exit 2); a port
            # that is there but failed to open (a box powering up, a flaky first contact) is retried
            # by its reader thread, and reported connected only once it is
            dev = devices.open_device(spec, require="present")
            if not dev.connected:
                warn(f"{spec} is there but did not open ({dev.last_error}); the show starts and it "
                     "connects once it answers")
            if getattr(dev, "scheme", "") == "panel" and getattr(dev, "server", None) is not None:
                from puppet.panel import announce

                announce(dev)  # its URL (with the LAN mode's token: the page is unreachable without it)
            opened.append(dev)
        return opened
    try:
        found = devices.discover()
    except Exception as err:  # discovery must never stop a show
        warn(f"device discovery failed ({err}); using the keyboard")
        found = []
    for info in found:
        if not getattr(info, "usable", True) or info.spec.startswith("keyboard") or info.kind == "audio":
            continue  # a microphone is used only when named: a room's sounds must not move the mouth
        try:
            opened.append(devices.open_device(info.spec))
        except devices.DeviceError as err:
            warn(f"skipping {info.spec}: {err}")
    return opened


class DeviceWatcher:
    """Boxes plugged in after the start: discovery is polled in a thread (opening may block), and
    each new box is adopted in the loop thread at a tick boundary with its default map."""

    def __init__(self, devs: list[Any], queue: Any, interval: float = 2.0) -> None:
        import threading

        self.devs, self.queue, self.interval = devs, queue, interval
        self.known = {d.spec for d in devs}
        self._new: list[Any] = []
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="device-watcher", daemon=True)

    def start(self) -> None:
        self._thread.start()

    def _run(self) -> None:
        import devices

        while not self._stop.wait(self.interval):
            try:
                found = devices.discover()
            except Exception:  # a flaky bus must not end the show
                continue
            for info in found:
                if (info.spec in self.known or not getattr(info, "usable", True) or info.spec.startswith("keyboard")
                        or info.kind == "audio"):
                    continue
                self.known.add(info.spec)
                try:
                    dev = devices.open_device(info.spec)
                except devices.DeviceError:
                    continue
                with self._lock:
                    self._new.append(dev)

    def adopt(self, core: Any) -> None:
        """Loop thread: give new boxes their default maps and start them."""
        with self._lock:
            new, self._new = self._new, []
        for dev in new:
            from puppet.mapping.defaults import default_map_name, load_default_map, merge

            name = default_map_name(dev.spec, dev.description)
            try:
                if name is not None:
                    core.mapper.add_spec(merge([(load_default_map(name), dev.spec)]))
                    core.mapper.declare_controls(dev.spec, dev.controls)
                dev.add_listener(self.queue)
                dev.start()
            except Exception as err:  # a box that fails to start must not stop the show
                print(f"puppet: cannot use {dev.spec}: {err}", file=sys.stderr)
                dev.close()
                continue
            self.devs.append(dev)
            core.mark(f"plugged in: {dev.spec}")
            print(f"puppet: new control box {dev.spec} ({name or 'no default map'})", file=sys.stderr)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5)


def _close_all(devs: list[Any]) -> None:
    for d in devs:
        try:
            d.close()
        except Exception:  # closing must not hide the real outcome
            pass


def run(args: argparse.Namespace) -> int:
    """`puppet live`. The garbage collector is off while the show starts: importing numpy and
    numba and loading the face make ~120k long-lived objects, and the collections they would
    trigger cost ~0.05-0.1 s of a 1 s start; the show's runtime collects once and takes over
    (`puppet.live._ShowRuntime`), and the collector is on again for anything after the show."""
    import gc

    streams = sys.stdout, sys.stderr
    sys.stdout, sys.stderr = _Unbroken(sys.stdout), _Unbroken(sys.stderr)
    try:
        if args.supervise:  # the supervisor runs for the whole show: it keeps its collector
            return _run(args)
        was_enabled = gc.isenabled()
        gc.disable()
        try:
            return _run(args)
        finally:
            if was_enabled:
                gc.enable()
    finally:
        sys.stdout, sys.stderr = streams
        live = sys.modules.get("puppet.live")  # (not imported: the command ended before the show)
        if live is not None and not live.join_background(BACKGROUND_WAIT):
            args.exit_at_once = True  # a compile outlived the wait: no interpreter teardown under it


class _Unbroken:
    """A show's terminal output that a reader who left cannot stop: `puppet live 2>&1 | head` or
    a closed log pipe. The first write that finds the pipe broken points the stream's file at
    /dev/null (later writes, the children's and the exit's flush go nowhere) and the show, its
    recording and its exports go on."""

    def __init__(self, stream: Any) -> None:
        self._stream = stream

    def write(self, text: str) -> int:
        try:
            return int(self._stream.write(text))
        except (BrokenPipeError, ConnectionResetError):
            self._gone()
            return len(text)

    def flush(self) -> None:
        try:
            self._stream.flush()
        except (BrokenPipeError, ConnectionResetError):
            self._gone()

    def _gone(self) -> None:
        try:
            os.dup2(os.open(os.devnull, os.O_WRONLY), self._stream.fileno())
        except (OSError, ValueError, AttributeError):
            pass

    def __getattr__(self, name: str) -> Any:
        return getattr(self._stream, name)


#: seconds the face may take to load before the show says that it is being prepared
SLOW_FACE_NOTICE = 3.0


def _load_face_saying(live: Any, args: argparse.Namespace, warn: Callable[[str], None]) -> Any:
    """live.load_face, with a line if it is slow: with empty caches (the first show after an
    install or update) building the scanned face took a minute of silence before any line."""
    import threading

    timer = threading.Timer(SLOW_FACE_NOTICE, warn, ["preparing the face: loading it (the first show after an "
                                                     "install or update builds it and its caches: a minute or more)"])
    timer.daemon = True
    timer.start()
    try:
        return live.load_face(args.rig, face=args.face)
    finally:
        timer.cancel()


def _run(args: argparse.Namespace) -> int:
    from puppet import live
    from puppet.errors import PuppetError

    def warn(msg: str) -> None:
        print(f"puppet: {msg}", file=sys.stderr)

    live.check_duration(args.duration)
    if args.face is not None and args.rig is None:  # a mistyped face is said before anything starts
        from puppet.faces import parse_face

        parse_face(args.face)
    if args.no_panel:  # each was dropped without a word: --no-panel won
        given = [opt for opt, on in (("--panel", args.panel is not None), ("--panel-lan", args.panel_lan),
                                     ("--panel-role", bool(args.panel_role))) if on]
        if given:
            raise PuppetError(f"--no-panel and {given[0]} contradict each other: leave out one of them")
    if args.panel_role:  # the form said before the face loads, and in a demo, which serves no page
        from puppet.panel.device import parse_roles

        try:
            parse_roles(args.panel_role)
        except ValueError as err:
            raise PuppetError(str(err)) from err
    if args.panel is not None and not 0 <= args.panel <= 65535:
        # said before the face loads, of the port the user typed (it was the page device's error,
        # naming a panel:// URL the user never wrote, after the face had loaded)
        raise PuppetError(f"--panel {args.panel}: a port is 1..65535 (0 takes any free port)")
    if args.supervise or args.resume:
        if args.demo:
            raise PuppetError("--demo plays once: leave out --supervise and --resume")
        if args.resume and not args.record:
            raise PuppetError("--resume continues the recording given with --record FILE")
    if args.record and (args.record.endswith(("/", os.sep)) or Path(args.record).is_dir()
                        or Path(args.record).name in ("", ".", "..")):
        # '.' was a ValueError traceback, '/tmp' 'a take is already there and cannot be kept aside',
        # 'takes/' a file named takes
        raise PuppetError(f"--record {args.record}: that names a folder; name the take's file, e.g. "
                          f"{Path(args.record) / 'take.jsonl'}")
    if args.record and not Path(args.record).parent.is_dir():
        raise PuppetError(f"--record {args.record}: the folder {Path(args.record).parent} does not exist; "
                          "create it or record elsewhere")
    if args.supervise:
        from puppet.supervise import run_supervised

        return run_supervised(args, warn)
    live.warm_up_in_background()  # numba's kernels load while the devices open and the face loads
    if args.standby:
        from puppet.supervise import stand_by

        if not stand_by(args, lambda: live.load_face(args.rig, face=args.face)):
            return 0
    if args.map:  # said before any demo or show starts (a pipe, `--map <(...)`, is read as it comes)
        from safefile import file_kind

        kind = file_kind(args.map)
        if kind == "missing":
            raise PuppetError(f"{args.map}: no such map file (`puppet learn --map FILE` makes one)")
        if kind == "folder":
            raise PuppetError(f"{args.map}: is a folder, not a map file")
        if kind == "file":
            # its own errors (TOML, a binding's fields, a filter's type) said now, not after the face
            # has loaded: that takes seconds on a busy machine (a minute on a new install), and the
            # "preparing the face" notice then came before the error line (a pipe is read once, later)
            from puppet.mapping import load_mapping

            load_mapping(args.map)
    windowed = not args.headless and live.display_available()
    if args.demo:
        if args.device:
            raise PuppetError("--demo plays its own scripted box: leave out --device")
        return _demo(args, live, windowed, warn)
    snapshot: Path | None = None
    record = args.record
    devs = _open_devices(list(args.device), warn)
    for d in devs:  # what a box needs from its user (e.g. a MIDI controller's LED mode)
        note = getattr(getattr(d, "profile", None), "note", "")
        if note:
            warn(f"{d.spec}: {note}")
    explicit_panel = getattr(args, "panel", None) is not None or getattr(args, "panel_lan", False)
    if not devs and not windowed and not explicit_panel:
        length = "about 20 s" if args.duration is None else f"at most {args.duration:g} s"
        warn(f"no control box and no display: performing the built-in demo ({length}) headless into a "
             "recording, an MP4 and a PNG here (`puppet live --demo` does this on purpose)")
        return _demo(args, live, False, warn, quiet=True)
    if not args.headless and not windowed:
        record = record or str(live.default_record_path())
        snapshot = Path(record).with_suffix(".png")
        warn(f"no display found (DISPLAY is not set): running headless, recording to {record} and "
             f"saving the last frame to {snapshot}; replay with `puppet replay {record} --out video.mp4`")
    face = _load_face_saying(live, args, warn)
    mapped = [(d.spec, d.description) for d in devs]  # these get their default maps
    if windowed and not any(d.spec.startswith("keyboard") for d in devs):
        import devices

        kb = devices.open_device("keyboard://")  # ESC / M always; the whole key map when alone
        if not devs:
            mapped.append((kb.spec, kb.description))
        devs.append(kb)
    try:
        _open_panel(args, face, devs, explicit_panel, warn)
        return _perform(args, live, face, devs, mapped, windowed, record, snapshot, warn, watch=not args.device)
    finally:
        _close_all(devs)


def _open_panel(args: argparse.Namespace, face: Any, devs: list[Any], explicit: bool, warn: Any) -> None:
    """Serve the performer's page (a `panel://` device) unless --no-panel, or the run is on the
    script clock of mock boxes and no page was asked for."""
    import devices
    from puppet.panel import announce
    from puppet.panel.device import parse_roles

    scripted = bool(devs) and all(getattr(getattr(d, "script", None), "speed", 1.0) == 0 for d in devs)
    if getattr(args, "no_panel", False) or (scripted and not explicit):
        return
    try:
        roles = parse_roles(getattr(args, "panel_role", []), face.vocab)
    except ValueError as err:
        raise devices.DeviceSpecError(str(err)) from err
    named = [d for d in devs if getattr(d, "scheme", "") == "panel"]
    if named and not explicit:
        # `--device 'panel://127.0.0.1:8765?face=mesh'` is the page the user asked for: serving the
        # default one beside it printed two URLs (the default moved to 8766); --panel-role roles it
        for page in named:
            page.roles = page.roles or dict(roles)
        return
    port = "" if args.panel is None else f":{args.panel}"
    host = "0.0.0.0" if args.panel_lan else "127.0.0.1"
    spec = f"panel://{host}{port}" + ("?lan=1" if args.panel_lan else "")
    try:
        # the page the user did not ask for is served after the first tick (puppet.panel.device)
        dev = devices.open_device(spec, vocab=face.vocab, roles=roles, serve_later=not explicit)
    except devices.DeviceError as err:
        if explicit:
            raise
        warn(f"no performer's page ({err})")
        return
    devs.append(dev)
    if not dev.serve_later:
        announce(dev)


#: how long the show's end waits for a background compile (the wrinkle layer's, a cold start's
#: kernels) before ending the process without the interpreter's teardown
BACKGROUND_WAIT = 60.0

#: on a cold start, how long the first tick waits at most for the page's server to have started
PAGE_START_WAIT = 5.0


def _perform(args: argparse.Namespace, live: Any, face: Any, devs: list[Any], mapped: list[tuple[str, str]],
             windowed: bool, record: str | None, snapshot: Path | None, warn: Any, watch: bool = False) -> int:
    import devices
    from puppet.mapping import Mapper
    from puppet.session import SessionWriter

    specs = [d.spec for d in devs]
    spec = live.build_mapping(face.vocab, args.map, mapped, system_keys=windowed)
    from puppet.panel import panel_devices, with_panel_map

    spec = with_panel_map(spec, face.vocab, devs)
    mapper = Mapper(spec, face.vocab)
    for d in devs:
        mapper.declare_controls(d.spec, d.controls)
    virtual = bool(devs) and all(getattr(getattr(d, "script", None), "speed", 1.0) == 0 for d in devs)
    from puppet.tick_rate import live_tick_rate

    # a page nobody asked for is served after the first frame (a fast start); but when the face's
    # kernels are being compiled (the first show after an install or update) it is served now, while
    # they compile and the tick cost is measured, and it has started before the first tick: its start
    # (aiohttp's import, the CA bundle: ~50 ms holding the interpreter) must not land on the show's
    # first ticks; so is the wrinkle layer built then (wrinkles_later)
    from puppet.panel import announce

    early = [p for p in panel_devices(devs) if p.server is None and p.serve_later and live.compiling_kernels()]
    starting = [page.serve_in_background(announce, warn) for page in early]

    # headless on the wall clock (the loop wakes on events) the fastest tick the face's measured step
    # affords (240 Hz for the procedural face, 120 Hz for the scanned head here); a window runs the
    # ticks due right before each frame, where a faster tick would only cost; a script's clock keeps 60 Hz
    rate = getattr(args, "tick_rate", None) or (live.TICK_RATE if virtual or windowed else live_tick_rate(face, warn))
    header = live.session_header(face, spec, rate, specs)
    if getattr(args, "performer", None):
        header["performer"] = str(args.performer)[:200]
    point = None
    if record and getattr(args, "resume", False):
        from puppet import resume

        point = resume.resume_point(record, face, getattr(args, "follower", None))
    from puppet import audio_take

    kept = None  # where a take already at --record went (the library follows it there)
    if point is None and record:
        from puppet.session import keep_previous

        # before the new sound is started: the earlier take's sound and pictures go with it (the
        # sound was kept aside on its own before, and the kept take then played the new one)
        kept = keep_previous(record, companions=True)
        if kept is not None:
            warn(f"{record} already held a take: kept as {kept}")
    sound = audio_take.attach(devs, record if point is None else None, header)  # a WAV beside the take
    if point is not None:
        rate = float(point.header.get("tick_rate", rate))  # a take goes on at the rate it was made at
        header["tick_rate"] = rate
        writer = resume.open_resumed(point, SessionWriter, header)
    if point is None:
        writer = SessionWriter(record, header) if record else None
    if writer is not None and record:  # the library knows the take from its first tick
        from puppet.library import begin_recording

        begin_recording(record, header, getattr(args, "performer", None), list(getattr(args, "tag", None) or []),
                        getattr(args, "library", None), warn, kept=kept)
    by_spec = {d.spec: d for d in devs}

    def lights(dev: str, ctl: str, on: bool) -> None:
        d = by_spec.get(dev)
        if d is None:  # a box adopted mid-show (the watcher appends it to devs)
            d = next((x for x in devs if x.spec == dev), None)
            if d is not None:
                by_spec[dev] = d
        if d is not None:
            try:
                d.set_light(ctl, on)
            except devices.DeviceError:
                pass

    import time

    win = live.open_live_window(face.model, devs) if windowed and not virtual else None
    try:  # the window is closed by run_window; until then, by this if the show fails to start
        t0 = time.monotonic()
        core = live.LiveCore(face, mapper, rate=rate, writer=writer, t0=0.0 if virtual else t0, lights=lights,
                             wrinkles_later=not virtual and not live.compiling_kernels(),
                             announce=warn)  # a scripted show too: the demo compiled for minutes unsaid
        if point is not None:
            resume.start_segment(core, point)
        if sound:
            core.before_tick.append(audio_take.clock_hook(sound))
        for page in panel_devices(devs):
            page.watch(core, devs, record)
            page.library = getattr(args, "library", None)  # the page's take list reads it
            if page.server is None and page.serve_later and page not in early:
                core.after_first_frame.append(lambda p=page: p.serve_in_background(announce, warn))
        stop = live.StopFlag()
        stop.install()
        watcher = None
        queue = devices.EventQueue()
        if watch and not virtual:
            watcher = DeviceWatcher(devs, queue)
            core.before_tick.append(watcher.adopt)
            watcher.start()
        if virtual:  # a scripted take runs start to end on the collector's own schedule
            import gc

            gc.enable()
    except BaseException:
        if win is not None:
            win.close()
        raise
    for th in starting:  # a cold start has waited seconds already: the page's start is done first
        th.join(PAGE_START_WAIT)
    try:
        if not virtual:
            live.prepare_show()
        if virtual:
            duration = args.duration or max(d.script.duration for d in devs) or 1.0
            live.run_virtual(core, live.scripted_events(devs), duration, stop=stop)
        elif win is not None:  # (a window that could not open has said why: the show runs headless)
            from puppet.live import run_window

            for d in devs:
                d.add_listener(queue)
                d.start()
            pictures = [p.face_feed for p in panel_devices(devs) if p.face_feed.mode == "picture"]
            run_window(core, queue.drain, args.duration, devs, fullscreen=args.fullscreen, stop=stop, win=win,
                       pictures=pictures, pipelined=args.pipelined)
        else:
            # real-time scheduling wherever it is permitted (None: the default, tried quietly), as
            # audio programs do: on a busy machine the ordinary scheduling delays ticks by 13-160 ms
            asked = getattr(args, "realtime", None)
            wanted = asked is not False
            if wanted:
                os.environ["PUPPET_REALTIME_DEVICES"] = "1"  # the readers: SCHED_FIFO a step below the loop
            for d in devs:
                d.add_listener(queue)
                d.start()
            why = live.realtime_priority() if wanted else None
            if why is not None and asked:
                warn(f"--realtime: real-time scheduling not permitted here ({why}); the show runs at the "
                     "ordinary priority")
            try:
                live.run_realtime(core, queue.drain, args.duration, stop=stop, wake=queue.wait_arrival)
            finally:
                if wanted:
                    live.ordinary_priority()
    finally:
        import gc

        gc.enable()  # the show is over: the collector is on for what follows (snapshot, export)
        stop.restore()
        if watcher is not None:
            watcher.close()
        if writer is not None:
            writer.close(core.tick_count)
        audio_take.finish(sound, core.tick_count / core.rate if sound else None)
        if writer is not None and record and writer.error is None:
            from puppet.library import register_recording

            register_recording(record, getattr(args, "performer", None), getattr(args, "library", None), warn,
                               tags=list(getattr(args, "tag", None) or []))
    p50, p99 = core.latency.percentile(50), core.latency.percentile(99)
    lat = f"; input-to-frame latency p50 {p50 * 1e3:.1f} ms, p99 {p99 * 1e3:.1f} ms" if p50 is not None else ""
    where = f" to {record}" if record else ""
    print(f"puppet: performed {core.tick_count} ticks ({core.tick_count / core.rate:.2f} s){where}{lat}")
    if snapshot is not None:
        try:
            from render.offscreen import OffscreenRenderer, save_image

            with OffscreenRenderer(face.model, (1280, 720)) as r:
                save_image(r.render_frame(core.state), snapshot)
            print(f"puppet: last frame saved to {snapshot}")
        except Exception as err:  # a missing GL must not lose the recording
            warn(f"could not render the snapshot ({err}); the recording is intact")
    return 0



def _demo(args: argparse.Namespace, live: Any, windowed: bool, warn: Any, quiet: bool = False) -> int:
    """The built-in demo through the real mock:// device -> SGI map -> simulator path. In a window
    it plays in real time (and records); headless it runs on script time, records, exports an MP4
    of the recording (re-simulated, as `puppet replay` would) and saves the last frame as a PNG."""
    import devices
    from puppet.demo import SCRIPT

    stamp = live.default_record_path().name.replace("puppet-", "puppet-demo-")
    record = Path(args.record or stamp)
    spec = f"mock://{SCRIPT}" + ("?speed=1" if windowed else "")
    dev = devices.open_device(spec)
    if args.duration is None or args.duration > dev.script.duration:
        args.duration = dev.script.duration
    if not quiet:
        where = "in the window" if windowed else "headless"
        warn(f"performing the built-in demo ({args.duration:.1f} s) {where}, recording to {record}")
    face = _load_face_saying(live, args, warn)  # the README's first command: minutes on a new install
    devs = [dev]
    mapped = [(dev.spec, dev.description)]
    if windowed:
        devs.append(devices.open_device("keyboard://"))  # ESC panic, M marker
    try:
        snapshot = None if windowed else record.with_suffix(".png")
        code = _perform(args, live, face, devs, mapped, windowed, str(record), snapshot, warn)
    finally:
        _close_all(devs)
    if code or windowed:
        print(f"puppet: replay with `puppet replay {record}`; make a video with "
              f"`puppet replay {record} --out {record.with_suffix('.mp4')}`")
        return code
    return _demo_files(record, warn)


def _demo_files(record: Path, warn: Any) -> int:
    """The demo's MP4, made by replaying its recording (as `puppet replay --out` does)."""
    from puppet.export.runner import ExportOptions, export
    from puppet.replay import build_performance
    from puppet.session import read_session

    mp4 = record.with_suffix(".mp4")
    try:
        export(build_performance(read_session(record), None), mp4, ExportOptions(fps=30.0))
        print(f"puppet: video written to {mp4}")
    except Exception as err:  # a missing GL or encoder must not lose the recording
        warn(f"could not write {mp4} ({err}); the recording is intact")
    print(f"puppet: demo recorded to {record}; replay it with `puppet replay {record}` "
          f"(or `puppet replay {record} --out other.mp4 --view wireframe`)")
    return 0
