"""The live loop: device events -> mapping -> channel values -> simulator, at a fixed tick (240 Hz
headless on the wall clock by default, 60 Hz in a window and on a script's clock; frames at the
display's rate).

`LiveCore` is the deterministic part shared with replay: one `tick(events)` applies the events at
the tick boundary, steps the mapping's filters with the tick's dt, records, and advances the
Simulator once. Drivers around it decide *when* ticks happen: `run_virtual` (mock scripts, as fast
as possible on script time), `run_realtime` (headless, wall clock), and the window driver in
`run_window` (ticks decoupled from the frame rate). Latency is event timestamp -> frame presented."""

from __future__ import annotations

import datetime as _dt
import math
import os
import signal
import time
from collections import deque
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from devices.events import ControlEvent, StatusEvent
from puppet.errors import ConfigError, PuppetError
from puppet.mapping import Mapper, MappingSpec, Vocabulary, load_mapping
from puppet.mapping.defaults import default_map_name, load_default_map, merge
from puppet.session import SessionWriter

TICK_RATE = 60.0
#: tick rates `puppet live --tick-rate` offers: the simulation may tick faster than frames are drawn
TICK_RATES = (60.0, 120.0, 240.0)
#: what a headless show on the wall clock ticks at unless told or measured (puppet.tick_rate) (a window, which runs the ticks due
#: right before each frame, and scripted runs on the script clock keep TICK_RATE): measured with benchmarks/live_latency.py (docs/live.md, "Tick rate"), 240 Hz with the
#: loop woken on events brings event -> simulated state p99 from ~18 ms to 2.4-3.0 ms and event ->
#: frame p99 under one 60 Hz refresh + 2 ms, for ~10% more CPU than 60 Hz (fewer RK2 substeps a tick)
LIVE_TICK_RATE = 240.0
#: the frame rate frames are drawn at when nothing else paces them (headless renders, a window
#: without vsync)
DISPLAY_RATE = 60.0
#: how often a window hands its frame to the performer's pages (their face view)
PICTURE_HZ = 30.0
CHECK_TICKS = 60  # a digest of the positions once a second lets replay prove it matches
Event = ControlEvent | StatusEvent

#: Keys that work in any window session, whatever the mapping says (unless it binds them itself).
SYSTEM_KEYS = """version = 1
name = "system keys"
device = "keyboard"
[[binding]]
control = "key:ESCAPE"
action = "panic"
label = "ESC panic"
[[binding]]
control = "key:M"
action = "marker"
label = "M marker"
"""


class LatencyMeter:
    """Input-to-frame latency over the last `window` events, in seconds."""

    def __init__(self, window: int = 600) -> None:
        self.samples: deque[float] = deque(maxlen=window)
        self.all: list[float] = []
        self.keep_all = False

    def add(self, seconds: float) -> None:
        if math.isfinite(seconds) and seconds >= 0.0:
            self.samples.append(seconds)
            if self.keep_all:
                self.all.append(seconds)

    def percentile(self, q: float) -> float | None:
        if not self.samples:
            return None
        return float(np.percentile(np.fromiter(self.samples, float), q))


@dataclass
class Face:
    """A compiled face and what a recording needs to find it again."""

    model: Any
    vocab: Vocabulary
    rig: dict[str, Any]


def load_face(rig_path: str | None = None, resolution: int = 0, face: Any = None,
              bound_forehead: bool = True) -> Face:
    """The face asked for: the rig file at rig_path (a one-line ConfigError if it is wrong), else
    `face` (a --face text or a puppet.faces.FaceChoice; None: the default face). Compiled faces
    come from the on-disk cache when it holds a trustworthy entry (puppet.face_cache).
    bound_forehead False: a scanned head's skin as before the forehead's bound layer
    (`sim.face.scan.rig.scan_params`), for a take recorded then (its header without "bending")."""
    import sim

    from puppet import face_cache
    from puppet.faces import FaceChoice, parse_face

    if rig_path:
        try:
            from sim.build import compile_model
            from sim.face.scan.rig import THIN_FOREHEAD_KEY, is_scan_rig, scan_params
            from sim.rig import load_model, load_rig

            rig = load_rig(rig_path)
            # a rig of the scanned head's skin (an earlier shipped ict_rig.npz, to replay a take
            # recorded on it bit for bit) compiles with the scanned head's skin parameters
            scan = is_scan_rig(rig)
            params = scan_params(bound_forehead)
            build = (lambda: compile_model(rig, params)) if scan else (lambda: load_model(rig_path))
            variant = THIN_FOREHEAD_KEY if scan and not bound_forehead else b""
            model = face_cache.rig_model(rig, Path(rig_path).read_bytes(), build, variant)
        except FileNotFoundError as err:
            raise ConfigError(f"{rig_path}: rig file not found") from err
        except (OSError, ValueError, KeyError) as err:
            msg = str(err) if str(err).startswith(str(rig_path)) else f"{rig_path}: cannot load the rig: {err}"
            raise ConfigError(msg) from err
        info = {"name": getattr(rig, "name", "rig"), "hash": model.hash, "path": str(Path(rig_path).resolve())}
        return Face(model, Vocabulary.from_model(model), info)
    choice = face if isinstance(face, FaceChoice) else parse_face(face, resolution)
    if choice.kind == "procedural":
        model = face_cache.default_model(choice.resolution)
        info = {"name": "default", "hash": model.hash, "path": None, **choice.header()}
    else:
        model = face_cache.scan_model(choice.weights if choice.weights.any() else None, bound_forehead)
        info = {"name": str(model.rig.name), "hash": model.hash, "path": None, **choice.header()}
    return Face(model, Vocabulary.from_model(model), info)


_COLD_START: dict[str, Any] = {}
_COLD_START_KNOWN = __import__("threading").Event()


def compiling_kernels(timeout: float = 10.0) -> bool:
    """True when `warm_up_in_background` found numba's cache without this version's kernels: the
    face's preparation will compile for seconds (the first show after an install or update), time
    in which other start-up work (the page's server) can be done instead of during the show."""
    if "started" not in _COLD_START:  # no warm-up ran in this process: nothing to tell
        return False
    return _COLD_START_KNOWN.wait(timeout) and _COLD_START.get("cold", False)


def warm_up_in_background() -> None:
    """Load the RK2 and wrinkle kernels from numba's cache in a thread (~0.3-0.7 s, most of a warm
    start) while the caller opens devices and loads the face; `prepare_kernels` waits for it."""
    import threading

    def run() -> None:
        try:
            from sim.integrator import kernels_cached, warm_up

            _COLD_START["cold"] = not kernels_cached()
            _COLD_START_KNOWN.set()
            warm_up(implicit=False)
            from sim.wrinkles.kernels import warm_up as warm_up_wrinkles

            warm_up_wrinkles()
        except Exception:  # prepare_kernels will compile or report it
            pass
        finally:
            _COLD_START_KNOWN.set()

    _COLD_START["started"] = True
    thread = threading.Thread(target=run, name="kernel-warm-up", daemon=True)
    _COLD_START["thread"] = thread
    start_background(thread)


#: threads a show starts that may still run compiled code (numba, LLVM) when the show ends
_BACKGROUND: list[Any] = []


def start_background(thread: Any) -> None:
    """Start `thread` and keep it, so the show's end can wait for it (`join_background`)."""
    _BACKGROUND.append(thread)
    thread.start()


def join_background(timeout: float = 60.0) -> bool:
    """Wait up to `timeout` seconds in all for the show's background threads (the kernels' warm-up,
    the wrinkle layer's build). A daemon thread still in native code (numba's LLVM, a C++ library
    running without the GIL) when Python 3.11 finalizes is ended by pthread_exit as it takes the GIL
    back; unwinding C++ frames that way aborts the process ("terminate called without an active
    exception", exit 134), which a show stopped right after its first frame met now and then. False
    when one is still running: the caller then ends the process without the interpreter's teardown."""
    import time

    end = time.monotonic() + timeout
    while _BACKGROUND:
        th = _BACKGROUND[0]
        th.join(max(0.0, end - time.monotonic()))
        if th.is_alive():
            return False
        _BACKGROUND.pop(0)
    return True


def build_mapping(vocab: Vocabulary, map_path: str | None, device_specs: Sequence[str | tuple[str, str]],
                  system_keys: bool = False) -> MappingSpec:
    """The user's mapping file, or the default map of every device (specs, or (spec, description)
    pairs so a HID gamepad is recognised by what it says it is); checked against the face."""
    parts: list[tuple[MappingSpec, str | None]] = []
    if map_path:
        spec = load_mapping(map_path)
        Mapper(spec, vocab)  # check targets now, with the user's file:line
        parts.append((spec, None))
    else:
        for item in device_specs:
            dev, desc = (item, "") if isinstance(item, str) else item
            name = default_map_name(dev, desc)
            if name is None:
                continue
            try:
                spec = load_default_map(name)
            except (FileNotFoundError, ConfigError):
                continue
            parts.append((spec, dev))
    if system_keys:
        bound = {b.control for s, _ in parts for b in s.bindings}
        sys_spec = _parse_system_keys()
        sys_spec.bindings = [b for b in sys_spec.bindings if b.control not in bound]
        if sys_spec.bindings:
            parts.append((sys_spec, None))
    merged = merge(parts, map_path or "default maps")
    return merged


def _parse_system_keys() -> MappingSpec:
    from puppet.mapping import parse_mapping

    return parse_mapping(SYSTEM_KEYS, "<system keys>")


#: the take header's "muscles": the implicit step adds each muscle's precomputed response
MUSCLES_AS = "responses"
#: the take header's "lids": the lids follow the eyes' turn (`sim.gaze_lids`); a take without it
#: was recorded before they did and is replayed with them still (puppet.replay)
LIDS_AS = "gaze"
#: the take header's "lid coupling": the lids' upper and lower, inner and outer parts are carried
#: sideways by the turning eye apart (`sim.gaze_lids.lid_couplings`); a take without it was recorded
#: with them held alike and is replayed so (puppet.replay)
LIDS_APART_AS = "upper and lower, inner and outer apart"
#: the take header's "gaze tissue": the tissue round each globe is carried by the turning eye (the
#: rig's `gaze`, `sim.gaze_lids.tissue_fields`); a take without it was recorded before and is
#: replayed without it (puppet.replay)
GAZE_TISSUE_AS = "carried by the turning eye"
#: the take header's "jaw": the implicit step starts from the last step's jaw opening and skin age
#: and adds the jaw's move as precomputed responses (sim.Simulator.jaw_responses)
JAW_AS = "responses from the last step's pose"
#: the take header's "jaw bending": the margin bending's rest side at an open jaw is made from the
#: jaw's turn (sim.Simulator.bending_turned); a take without it is replayed with the product of the
#: bending matrix and the turned rest shape, as it was recorded (puppet.replay)
JAW_BENDING_AS = "from the turn"
#: the take header's "solve": the implicit step's substeps solve from the symmetric factor alone
#: (sim.Simulator.symmetric_solve: L and D, U's values unread); a take without it is replayed with
#: the solve from L and U, as it was recorded (puppet.replay)
SOLVE_AS = "symmetric factor"
#: the take header's "responses": the implicit step reads the inputs' precomputed responses in
#: float32 (sim.Simulator.single_responses); a take without it is replayed with them in float64,
#: as it was recorded (puppet.replay)
RESPONSES_AS = "float32"
#: the take header's "jaw constants": at a jaw opening the implicit step reads its target, support
#: normals and constant forces linearly between precomputed openings (sim.Simulator.
#: constants_from_grid); a take without it is replayed with them turned at each opening (puppet.replay)
JAW_CONSTANTS_AS = "from the grid"
#: the take header's "bending": a scanned head's forehead bends as its bound layer
#: (sim.antifold.bound_layer); a take without it, made on another face hash, was recorded on the
#: thinner forehead and is replayed on it (puppet.replay)
BENDING_AS = "forehead bound layer"


def session_header(face: Face, spec: MappingSpec, rate: float, devices: Sequence[str]) -> dict[str, Any]:
    return take_header(face, rate, {"source": spec.source, "text": spec.text}, devices)


def take_header(face: Face, rate: float, mapping: dict[str, str], devices: Sequence[str]) -> dict[str, Any]:
    """The header every take starts with (the live show's, a fit's, a voice's): program, start
    time, rig, channels, tick rate, the mapping (source and text) and the devices."""
    from puppet import __version__

    return {
        "program": f"facepuppet {__version__}",
        "start_time": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="milliseconds"),
        "rig": face.rig,
        "channels": [c.name for c in face.vocab.channels],
        "tick_rate": rate,
        "mapping": dict(mapping),
        "devices": list(devices),
        # how the implicit step adds the muscles (sim.implicit): a take without it is replayed with
        # the muscles summed into the frame's forces, as it was recorded (puppet.replay)
        "muscles": MUSCLES_AS,
        "lids": LIDS_AS,
        "lid coupling": LIDS_APART_AS,
        "gaze tissue": GAZE_TISSUE_AS,
        # how it moves the jaw and ages the skin: a take without it is replayed with the jaw and the
        # age taken whole at each step, as it was recorded (puppet.replay)
        "jaw": JAW_AS,
        "jaw bending": JAW_BENDING_AS,
        "solve": SOLVE_AS,
        "responses": RESPONSES_AS,
        "jaw constants": JAW_CONSTANTS_AS,
        # how a scanned head's forehead bends: a take without it is replayed on the forehead it
        # was recorded on (puppet.replay)
        "bending": BENDING_AS,
    }


class Spans:
    """Where the time goes after a tick boundary: perf_counter seconds per named span, one entry
    per tick (or per frame for the spans a driver adds). Off unless a LiveCore is given one."""

    def __init__(self) -> None:
        self.data: dict[str, list[float]] = {}

    def add(self, name: str, seconds: float) -> None:
        lst = self.data.get(name)
        if lst is None:
            lst = self.data[name] = []
        lst.append(seconds)


def _positions_digest(positions: np.ndarray) -> Callable[[], str]:
    """The `chk` digest of positions copied now, computed later (off the critical path); the same
    text as puppet.replay.state_digest."""
    import hashlib

    def digest() -> str:
        return hashlib.sha1(positions.tobytes()).hexdigest()[:16]

    return digest


def prepare_kernels(model: Any, dt: float) -> None:
    """Every compiled kernel a show's ticks can call, compiled (the first show after an install or
    update: tens of seconds on a slow machine) or loaded from numba's cache now, before the first
    tick, so nothing compiles on the live path: the integrator this face and tick use (RK2 or
    implicit, by one step of a throw-away simulator; the show's own starts fresh, as replay's
    does) and the wrinkle kernel (its layer may be built later, `wrinkles_later`). The throw-away
    simulator steps at rest and then with every channel moved a third of its range, so kernels that
    run only once a channel moves (the jaw's turn, which a voice or a dial starts mid-show) are
    compiled too, then with the jaw's opening alone moved (the step by its responses, which places
    the held nodes on their own)."""
    import sim
    from sim.channels import CHANNEL_SPECS

    warming = _COLD_START.get("thread")
    if warming is not None:  # the background load finishes first, so no compile of it lands in the show
        warming.join()
    s, state, control = sim.Simulator(model, dt, wrinkles=False), model.rest_state(), sim.FaceControl(model)
    s.step(state, control)
    control.values[:] = [c.default + (c.hi - c.default) / 3 for c in CHANNEL_SPECS]
    s.step(state, control)
    s.step(state, control)  # the jaw held: the next step can be prepared
    s.prepare(state)  # what the loop computes between ticks (`LiveCore.prepare_next`)
    s.step(state, control)
    control.values[:] = [c.default for c in CHANNEL_SPECS]  # the jaw's opening alone moved: its responses
    control.set("jaw", 0.5)
    s.prepare(state)
    s.step(state, control)
    if model.rig.wrinkles:
        from sim.wrinkles.kernels import warm_up

        warm_up()


#: a test hook: `PUPPET_CRASH_AT_TICK=N` makes the live loop raise at tick N (testing --supervise)
CRASH_ENV = "PUPPET_CRASH_AT_TICK"


def _crash_tick() -> int:
    raw = os.environ.get(CRASH_ENV, "")
    return int(raw) if raw.isdigit() else -1


class LiveCore:
    """The fixed-tick core: same Simulator, same start state, same values per tick as replay.

    `tick` does only what the frame needs: apply the events, step the filters, one simulator step.
    What the recording needs is kept as is (events, the value array, a copy of the positions for
    the digest) and turned into JSON by `after_frame`, which the drivers call once the frame is
    published (the writer is put in deferred mode here)."""

    def __init__(self, face: Face, mapper: Mapper, *, rate: float = TICK_RATE,
                 writer: SessionWriter | None = None, t0: float = 0.0,
                 lights: Callable[[str, str, bool], None] | None = None, wrinkles_later: bool = False,
                 announce: Callable[[str], None] | None = None) -> None:
        import sim

        self.face, self.mapper, self.rate, self.dt = face, mapper, rate, 1.0 / rate
        # wrinkles_later: the wrinkle layer (~0.5-1 s to build and load) is made in a thread and
        # switched on at a tick boundary once ready, so the show starts without waiting for it;
        # wrinkles only displace the drawn surface, never the simulated positions or the recording
        self._wrinkles_ready = False
        t_prep = time.perf_counter()
        if announce is not None:
            announce("preparing the face")
        self.sim = sim.Simulator(face.model, self.dt, wrinkles=not wrinkles_later)
        prepare_kernels(face.model, self.dt)
        #: seconds the kernels took to compile or load before the first tick
        self.prepare_seconds = time.perf_counter() - t_prep
        if announce is not None and self.prepare_seconds > 1.0:
            announce(f"the face is ready ({self.prepare_seconds:.1f} s; compiled parts are kept for later shows)")
        self._wrinkles_thread = None
        if wrinkles_later and face.model.rig.wrinkles:  # started after the first frame
            import threading

            self._wrinkles_thread = threading.Thread(target=self._build_wrinkles, name="wrinkle-layer", daemon=True)
        self.state = face.model.rest_state()
        self.control = sim.FaceControl(face.model)
        self.writer, self.t0, self.lights = writer, t0, lights
        if writer is not None:
            writer.defer = True
        self.tick_count = 0
        self.latency = LatencyMeter()
        #: event -> the simulated state that includes it (the tick's step done), seconds
        self.state_latency = LatencyMeter()
        self.unpresented: list[float] = []
        self.frames = 0  # frames presented (the performer's page shows the rate)
        self.values = np.array(mapper.values, copy=True)
        self.markers: list[tuple[int, str]] = []
        #: run in the loop thread at each tick boundary (e.g. adopting a box plugged in mid-show)
        self.before_tick: list[Callable[[LiveCore], None]] = []
        #: the time of position 0 on the show's schedule (tick k is due at clock_origin + k * dt), on
        #: the loop's clock (monotonic in a show), set by the wall-clock loops and moved on when they
        #: drop wall time; None on script time. The sound of a take is placed by it (puppet.audio_take).
        self.clock_origin: float | None = None
        #: run once, after the first frame is published (what need not delay the first tick)
        self.after_first_frame: list[Callable[[], None]] = []
        #: set to a Spans to time the parts of each tick (benchmarks/live_latency.py)
        self.spans: Spans | None = None
        #: restored channel values kept until the performer takes them over (puppet.resume)
        self.hold: Any = None
        #: the wrinkle surface (drawn only) made for the ticks that are drawn, not every tick: set by
        #: the headless loop, which ticks faster than it draws and calls `finish_surface` before a
        #: frame. Meanwhile state.surface stays that of the last tick drawn (what a page watching
        #: the face between frames sees)
        self.surface_later = False
        self._surface_due = False
        self._crash_at = _crash_tick()

    def _build_wrinkles(self) -> None:
        try:
            from sim.wrinkles.layer import warm_up

            warm_up(self.face.model)
        except Exception as err:  # the show goes on without wrinkles
            import sys

            print(f"puppet: warning: no wrinkles this show ({err})", file=sys.stderr)
            return
        self._wrinkles_ready = True

    def tick(self, events: Iterable[Event]) -> None:
        """Apply `events` at this tick boundary, then advance one tick."""
        sp = self.spans
        if sp is not None:
            pc = time.perf_counter
            t_a = pc()
        if self._wrinkles_ready and not self.sim.wrinkles:
            self.sim.wrinkles = True
        for hook in self.before_tick:
            hook(self)
        k = self.tick_count
        writer, mapper, unpresented = self.writer, self.mapper, self.unpresented
        n_before = len(unpresented)
        for ev in events:
            if writer is not None:
                writer.event(k, ev, self.t0)
            mapper.feed(ev)
            if isinstance(ev, ControlEvent):
                unpresented.append(ev.t)
        if sp is not None:
            t_b = pc()
        if k == self._crash_at:
            import sys

            print(f"puppet: {CRASH_ENV}: crashing at tick {k}", file=sys.stderr, flush=True)
            raise RuntimeError(f"{CRASH_ENV}: the crash asked for at tick {k}")
        values = mapper.step(self.dt)
        if self.hold is not None:
            values = self.hold.apply(values)
        for label in mapper.take_markers():
            self.mark(label)
        if writer is not None:
            writer.values(k, values)
        self.values = values
        self.control.values[...] = values
        if sp is not None:
            t_c = pc()
        n_new = len(unpresented) - n_before
        self.sim.step(self.state, self.control, surface=False)
        if n_new:
            done = time.monotonic()
            for te in unpresented[-n_new:]:
                self.state_latency.add(done - te)
        if sp is not None:
            t_d = pc()
        if self.surface_later:  # the wrinkles only displace what is drawn: after the state is ready
            self._surface_due = True
        else:
            self.sim.surface(self.state)
        self.tick_count = k + 1
        if writer is not None:
            if self.tick_count % CHECK_TICKS == 0:
                writer.check(self.tick_count, _positions_digest(self.state.positions.copy()))
            writer.tick(self.tick_count)
        if self.lights is not None:
            for dev, ctl, on in mapper.light_changes():
                self.lights(dev, ctl, on)
        if sp is not None:
            t_e = pc()
            sp.add("events", t_b - t_a)
            sp.add("mapping", t_c - t_b)
            sp.add("sim step", t_d - t_c)
            sp.add("tick tail", t_e - t_d)

    def finish_surface(self) -> None:
        """The wrinkle surface of the last tick, when `surface_later` left it for the frame."""
        if self._surface_due:
            self._surface_due = False
            self.sim.surface(self.state)

    def prepare_next(self) -> None:
        """Between ticks: the next step's part that no input changes (`sim.Simulator.prepare`), so a
        tick that takes an event starts from what the event changes. The state and the recording
        are the same bits with or without it."""
        if self.spans is None:
            self.sim.prepare(self.state)
            return
        t = time.perf_counter()
        self.sim.prepare(self.state)
        self.spans.add("prepared between ticks", time.perf_counter() - t)

    def after_frame(self) -> None:
        """The frame is published: write the recording's records kept since the last call and
        hand it to the OS; then, after the first frame, start building the wrinkle layer
        (wrinkles_later) and run `after_first_frame` (their threads start once the tick is written)."""
        if self.writer is not None:
            if self.spans is not None:
                t = time.perf_counter()
                self.writer.service()
                self.spans.add("recording (after frame)", time.perf_counter() - t)
            else:
                self.writer.service()
        if self._wrinkles_thread is not None:
            with _OrdinaryThreads():
                start_background(self._wrinkles_thread)
            self._wrinkles_thread = None
        if self.after_first_frame:
            hooks, self.after_first_frame = self.after_first_frame, []
            with _OrdinaryThreads():
                for hook in hooks:
                    hook()

    def mark(self, label: str) -> None:
        self.markers.append((self.tick_count, label))
        if self.writer is not None:
            self.writer.marker(self.tick_count, label)

    def presented(self, t: float) -> None:
        """A frame showing every tick so far reached the screen (or the encoder) at time t."""
        self.frames += 1
        for te in self.unpresented:
            self.latency.add(t - te)
        self.unpresented.clear()


@dataclass
class StopFlag:
    """Set by SIGINT/SIGTERM so a run ends cleanly (recording closed) instead of dying."""

    stopped: bool = False
    _old: dict[int, Any] = field(default_factory=dict)

    def install(self) -> None:
        for sig in (signal.SIGINT, signal.SIGTERM):
            try:
                self._old[sig] = signal.signal(sig, self._handle)
            except ValueError:  # not the main thread
                pass

    def _handle(self, signum: int, frame: object) -> None:
        self.stopped = True

    def restore(self) -> None:
        for sig, old in self._old.items():
            signal.signal(sig, old)


def scripted_events(devices: Sequence[Any]) -> list[Event]:
    """Every event of mock devices' scripts on script time, in time order (virtual clock)."""
    out: list[tuple[float, int, Event]] = []
    n = 0
    for dev in devices:
        script = dev.script
        for it in script.items:
            if it.status:
                ev: Event = StatusEvent(dev.spec, it.status, it.t, "scripted")
            else:
                info = script.controls[it.control]
                ev = ControlEvent(dev.spec, it.control, info.kind, it.value, it.delta, it.raw, it.t)
            out.append((it.t, n, ev))
            n += 1
    out.sort(key=lambda x: (x[0], x[1]))
    return [e for _, _, e in out]


def run_virtual(core: LiveCore, events: Sequence[Event], duration: float,
                on_frame: Callable[[LiveCore], None] | None = None, stop: StopFlag | None = None) -> None:
    """Run ticks as fast as possible on script time: tick k applies events with t <= k*dt."""
    n_ticks = max(1, int(round(duration * core.rate)))
    i = 0
    if core.tick_count:  # a resumed take: the events of the ticks already performed are gone
        while i < len(events) and events[i].t <= (core.tick_count - 1) * core.dt + 1e-12:
            i += 1
    for k in range(core.tick_count, n_ticks):
        if stop is not None and stop.stopped:
            break
        boundary = k * core.dt + 1e-12
        batch = []
        while i < len(events) and events[i].t <= boundary:
            batch.append(events[i])
            i += 1
        core.tick(batch)
        if on_frame is not None:
            on_frame(core)
        core.after_frame()


#: the last part of a wait before a tick boundary is spent spinning: a sleep wakes up late by the
#: scheduler's latency (often 0.1-1 ms, more on a busy machine), a spin does not
SPIN_S = 0.0015
#: while the loop runs, a thread waiting for the GIL gets it after at most this long (CPython's
#: default is 5 ms: a device thread holding the GIL at a tick boundary would delay the tick by that)
SWITCH_INTERVAL_S = 0.0005
#: while the loop runs, garbage is collected after a frame, not inside a tick (`_ShowRuntime`):
#: the young generations every GC_FRAMES frames, all but the objects frozen at the start every
#: GC_FULL_FRAMES
GC_FRAMES = 60
GC_FULL_FRAMES = 3600


def wait_until(deadline: float, clock: Callable[[], float] = time.monotonic,
               sleep: Callable[[float], None] = time.sleep, stop: StopFlag | None = None,
               spin: float = SPIN_S, ready: Callable[[], bool] | None = None) -> float:
    """Wait for an absolute deadline (no drift from relative sleeps): sleep to within `spin` of it,
    then spin, yielding the GIL to the device threads. Returns the clock when it returned. `ready`
    (e.g. whether input arrived) is asked while spinning: the wait ends as soon as it says yes. With
    an injected sleep (tests' fake clocks) it only sleeps: a fake clock does not move while spinning."""
    real = sleep is time.sleep
    while True:
        now = clock()
        rem = deadline - now
        if rem <= 0 or (stop is not None and stop.stopped):
            return now
        if rem <= spin and ready is not None and ready():
            return now
        if rem > spin or not real:
            sleep(min(rem - spin, 0.05) if real else min(rem, 0.05))
        else:
            time.sleep(0)  # releases the GIL for a moment; returns at once


class _ShowRuntime:
    """How the process runs while a live loop runs (all restored after):

    - a shorter GIL hand-over (SWITCH_INTERVAL_S);
    - no automatic garbage collection inside a tick. What exists when the show starts is frozen out
      of the collector (`gc.freeze`; `prepare_show` freezes it uncollected, before the devices
      start), automatic collection is off, and `after_frame` (called once a frame is out) collects
      the young generations every GC_FRAMES frames and everything not frozen every GC_FULL_FRAMES.
      Left automatic, a full collection of the ~120k objects numba, numpy and the face leave took
      48-69 ms and a middle one 1-2 ms, landing on whatever tick was running."""

    def __enter__(self) -> _ShowRuntime:
        import gc
        import sys

        self.old = sys.getswitchinterval()
        sys.setswitchinterval(min(self.old, SWITCH_INTERVAL_S))
        self.gc_was_enabled = gc.isenabled()
        gc.collect(1)  # the young generations only: ~1 ms, the devices may already be running
        gc.freeze()
        gc.disable()
        self.frames = 0
        return self

    def after_frame(self) -> None:
        import gc

        self.frames += 1
        if self.frames % GC_FULL_FRAMES == 0:
            gc.collect()
        elif self.frames % GC_FRAMES == 0:
            gc.collect(1)

    def __exit__(self, *exc: object) -> None:
        import gc
        import sys

        gc.unfreeze()
        if self.gc_was_enabled:
            gc.enable()
        sys.setswitchinterval(self.old)


#: `puppet live --realtime`: the loop's thread runs under SCHED_FIFO at this priority, a step above the
#: devices' reader threads (PUPPET_REALTIME_DEVICES: 10), since FIFO does not share a core between equals
LOOP_RT_PRIORITY = 11


def realtime_priority() -> str | None:
    """Run the calling thread (the live loop's) under SCHED_FIFO at LOOP_RT_PRIORITY, so other
    programs on a busy machine cannot delay a tick or its wake-up; None when it is, else why not
    (it needs CAP_SYS_NICE or an rtprio limit, e.g. the `audio` group of a music machine)."""
    if not hasattr(os, "sched_setscheduler"):
        return "not on this system"
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(LOOP_RT_PRIORITY))  # 0: this thread
    except OSError as err:
        return str(err)
    return None


def ordinary_priority() -> None:
    """Back to the ordinary scheduling (after a show run with `realtime_priority`)."""
    if hasattr(os, "sched_setscheduler"):
        try:
            os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
        except OSError:
            pass


#: how far below a real-time loop the recording's writer thread runs (`_BelowLoop`)
WRITER_BELOW_LOOP = 2


class _BelowLoop:
    """While a thread the loop waits on is started from the loop's thread (the recording's writer:
    the loop waits for it at a hand-over, and for the interpreter's lock while it holds it): under
    a real-time loop it is real-time too, WRITER_BELOW_LOOP steps below, so the loop still preempts
    it but the machine's other programs cannot keep it off the cores while the loop waits for it.
    Started at the ordinary priority, it was: on a loaded machine (load 10-15 on 2 cores) the loop
    waited 30-174 ms at a hand-over or at the lock while the writer waited for a core."""

    def __enter__(self) -> None:
        self.policy = os.sched_getscheduler(0) if hasattr(os, "sched_getscheduler") else None
        if self.policy in (getattr(os, "SCHED_FIFO", None), getattr(os, "SCHED_RR", None)):
            self.param = os.sched_getparam(0)
            try:
                os.sched_setscheduler(0, self.policy,  # type: ignore[arg-type]
                                      os.sched_param(max(1, self.param.sched_priority - WRITER_BELOW_LOOP)))
            except OSError:
                self.policy = None
        else:
            self.policy = None

    def __exit__(self, *exc: object) -> None:
        if self.policy is not None:
            try:
                os.sched_setscheduler(0, self.policy, self.param)
            except OSError:
                pass


class _OrdinaryThreads:
    """While threads are started from the loop's thread: they must not inherit a real-time priority
    (the wrinkle layer's build, the page's server would then hold a core against the loop)."""

    def __enter__(self) -> None:
        self.policy = os.sched_getscheduler(0) if hasattr(os, "sched_getscheduler") else None
        if self.policy is not None and self.policy != os.SCHED_OTHER:
            self.param = os.sched_getparam(0)
            ordinary_priority()

    def __exit__(self, *exc: object) -> None:
        if self.policy is not None and self.policy != os.SCHED_OTHER:
            try:
                os.sched_setscheduler(0, self.policy, self.param)
            except OSError:
                pass


def prepare_show() -> None:
    """Freeze what the start made out of the collector, before the devices start, without collecting
    it first. The collector is off while a show starts (`puppet.cmd_live.run`), so every object the
    imports and the face made is still in the youngest generation and any collection, even of the
    young generations only, would walk all ~110k of them: 0.07-0.23 s of a 1 s start. The few
    thousand unreachable objects the imports leave (about 2,300) stay frozen with the rest until the
    show ends (`_ShowRuntime.__exit__` unfreezes); the live loop then collects only what the show
    itself makes."""
    import gc

    gc.freeze()


def run_realtime(core: LiveCore, drain: Callable[[], list[Event]], duration: float | None,
                 clock: Callable[[], float] = time.monotonic, sleep: Callable[[float], None] = time.sleep,
                 on_frame: Callable[[LiveCore], None] | None = None, stop: StopFlag | None = None,
                 frame_rate: float | None = None, wake: Callable[[float], bool] | None = None,
                 ahead_when_idle: bool = False) -> None:
    """Headless, on the wall clock: tick k happens at t0 + k*dt and takes every event that has
    arrived; a loop more than 4 ticks late drops wall time (re-anchors) rather than lag behind.

    The critical path from a boundary is kept short: wait for it on an absolute deadline (sleep, then
    a short spin), drain the input at that moment, tick, render (`on_frame`, which should finish the
    frame, e.g. read it back), and only then stamp the frame as presented.

    `frame_rate` (None: a frame per tick): frames are drawn at this rate (the display's) while the
    simulation ticks at `core.rate` (e.g. 240 Hz ticks, 60 Hz frames): a frame follows the first tick
    at or after each frame time, and a tick that took events is drawn at once when the last frame
    is at least half a frame period old (an event's frame does not wait for the schedule). `wake(timeout)` (e.g. EventQueue.wait_arrival): an event that arrives
    while the loop waits starts the next tick at once instead of at its boundary, never more than one
    tick ahead of the schedule: simulated time leads the wall clock by less than a tick, the tick
    rate holds on average, and the recording keeps the tick each event was applied at, as ever.

    Between ticks the loop makes the next step's part that no input changes (`LiveCore.prepare_next`),
    also when an input is already waiting (the step would do that part all the same), and drains
    the input after it: what arrives meanwhile joins the same tick. `ahead_when_idle`: only when no
    input waits, the tick then doing the whole step (as before; benchmarks/live_latency.py compares).

    With frames slower than ticks the wrinkle surface (drawn only) is made for the ticks drawn
    (`LiveCore.surface_later`), right before `on_frame`."""
    limit = None if duration is None else int(round(duration * core.rate))
    per_frame = None if frame_rate is None or frame_rate >= core.rate else core.rate / frame_rate
    if core.writer is not None:  # the loop's thread never writes the file itself (a write can wait on the disk)
        with _BelowLoop():
            core.writer.write_behind()
    core.surface_later = per_frame is not None
    try:
        _realtime_loop(core, drain, limit, per_frame, clock, sleep, on_frame, stop, wake, ahead_when_idle)
    finally:
        core.surface_later = False
        core.finish_surface()


def _realtime_loop(core: LiveCore, drain: Callable[[], list[Event]], limit: int | None, per_frame: float | None,
                   clock: Callable[[], float], sleep: Callable[[float], None],
                   on_frame: Callable[[LiveCore], None] | None, stop: StopFlag | None,
                   wake: Callable[[float], bool] | None, ahead_when_idle: bool) -> None:
    """The loop of `run_realtime`."""
    with _ShowRuntime() as runtime:
        start = clock()
        k0 = core.tick_count  # a resumed take starts at its first new tick
        core.clock_origin = start - k0 * core.dt
        next_frame = 0.0  # in ticks since k0
        last_frame = -math.inf  # the tick (since k0) last drawn
        while True:
            if stop is not None and stop.stopped:
                break
            if limit is not None and core.tick_count >= limit:
                break
            if not (ahead_when_idle and wake is not None and wake(0.0)):
                core.prepare_next()  # what no input changes; an input arriving meanwhile is drained after
            boundary = start + (core.tick_count - k0) * core.dt
            if wake is not None:
                now = wait_until(boundary - core.dt, clock, sleep, stop)  # at most one tick ahead
                if not (boundary - now > SPIN_S and wake(boundary - now - SPIN_S)):
                    # the last SPIN_S before the boundary is spun: input arriving then starts the
                    # tick at once too (it waited up to SPIN_S for the boundary: 18 % of events at 120 Hz)
                    now = wait_until(boundary, clock, sleep, stop, ready=lambda: wake(0.0))
            else:
                now = wait_until(boundary, clock, sleep, stop)
            if stop is not None and stop.stopped:
                break
            if core.spans is not None:
                core.spans.add("woke late", max(0.0, now - boundary))
            if now - boundary > 4 * core.dt:  # fell behind (machine busy): re-anchor the schedule
                start, k0, next_frame, last_frame = now, core.tick_count, 0.0, -math.inf
                core.clock_origin = start - k0 * core.dt
            # everything that arrived by now goes into this tick: waiting for the next boundary would
            # only add latency, and the recording keeps the tick each event was applied at
            events = drain()
            core.tick(events)
            if per_frame is not None:
                done = core.tick_count - k0
                # a tick that took events is drawn at once when the last frame is at least half a
                # frame old (the event's frame need not wait for the frame schedule; frames stay
                # under twice the display's rate); the schedule restarts from that frame
                if events and done - last_frame >= per_frame / 2:
                    next_frame = done + per_frame
                elif done < next_frame:
                    continue
                else:
                    next_frame += per_frame * max(1, int((done - next_frame) // per_frame) + 1)
                last_frame = done
            core.finish_surface()
            if on_frame is not None:
                on_frame(core)
            core.presented(clock())
            core.after_frame()  # the recording's JSON, flush: after the frame, not before it
            runtime.after_frame()


def display_available() -> bool:
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def default_record_path() -> Path:
    stamp = _dt.datetime.now().strftime("%Y%m%d-%H%M%S")
    return Path(f"puppet-{stamp}.jsonl")


def check_duration(duration: float | None) -> None:
    if duration is not None and not (duration > 0 and math.isfinite(duration)):
        raise PuppetError(f"--duration must be a positive number of seconds, got {duration}")



# --- the window drivers --------------------------------------------------------------------------

WINDOW_KEYS = "ESC eases to neutral   M marker   F1 help   F3 HUD   F4 view   F11 fullscreen   F10 quit"
#: keys both windows answer (`_common_key`); the window's own keys (1-5, R, H, V, Esc) are off
COMMON_HELP = ["F1 or ?: this help   F3: HUD on/off   F4: next view (shaded, wireframe, muscles, trails, heat)",
               "F5: reset the view   F11: fullscreen   F10: quit   mouse: drag to orbit, scroll to zoom"]
LIVE_HELP = ["ESC: ease back to neutral (panic)   M: drop a marker", *COMMON_HELP]
KEYMAP_HELP = "letters, digits, arrows, SPACE: the key map above (the keyboard is the control box)"
REPLAY_KEYS = "SPACE pause   LEFT/RIGHT seek 1 s   UP/DOWN speed   HOME restart   N next marker   ESC quit"
REPLAY_HELP = [REPLAY_KEYS, *COMMON_HELP]


def _window_or_none(model: Any, title: str, key_help: list[str]) -> Any:
    """A FaceWindow, or None (with one line saying why) when no window can be opened here."""
    import sys

    try:
        from render.window import FaceWindow, NoDisplayError
    except ImportError as err:
        print(f"puppet: no face window in this build ({err}): running headless", file=sys.stderr)
        return None
    try:
        # our keys, not the window's: ESC is the panic key here, letters and digits belong to the
        # key map; the window's help lists ours
        win = FaceWindow(model, title=title, builtin_keys=False, key_help=key_help)
    except NoDisplayError as err:
        print(f"puppet: {err}: running headless", file=sys.stderr)
        return None
    return win


def _common_key(win: Any, name: str) -> bool:
    """Window keys shared by live and replay; True if handled."""
    from render.renderer import VIEWS

    if name == "f10":
        win.request_close()
    elif name == "f11":
        win.toggle_fullscreen()
    elif name == "f1":  # the window shows the key help it was given (ours)
        win.show_help = not win.show_help
    elif name == "f5":
        win.renderer.camera.reset()
    elif name == "f3":
        win.show_hud = not win.show_hud
    elif name == "f4":
        r = win.renderer
        r.view = VIEWS[(VIEWS.index(r.view) + 1) % len(VIEWS)]
    else:
        return False
    return True


def live_hud(core: LiveCore, devs: Sequence[Any], keymap: bool, help: bool = False) -> Any:
    """What the HUD shows live: active channels, each device connected/lost, latency, the key map
    when the keyboard is the control box, and bindings waiting for pickup or on a lost device."""
    from render.hud import HudInfo, active_channels

    mapper = core.mapper
    status = [_device_status(d, mapper) for d in devs]
    p50, p99 = core.latency.percentile(50), core.latency.percentile(99)
    lines = []
    if p50 is not None and p99 is not None:
        lines.append(f"input->frame p50 {p50 * 1e3:.1f} ms  p99 {p99 * 1e3:.1f} ms")
    if keymap:  # four keys a line, so the whole map fits on the screen
        labels = [b.spec.label for b in mapper.bindings if b.spec.label]
        lines += ["   ".join(labels[i:i + 4]) for i in range(0, len(labels), 4)]
    for b in mapper.bindings:
        what = b.spec.target or b.spec.action
        if b.device is not None and not mapper.status.get(b.device, True):
            lines.append(f"LOST {b.spec.control} -> {what} ({b.device})")
        elif b.kind == "absolute" and not b.engaged:
            lines.append(f"move {b.spec.control} to pick up {what}")
    lines.append(WINDOW_KEYS)
    if help:  # the window adds its key help itself (FaceWindow.key_help); this is for other HUDs
        lines += LIVE_HELP
    return HudInfo(channels=active_channels(core.face.model.channels, core.values),
                   devices=status, latency_ms=None if p50 is None else p50 * 1e3, lines=lines[-24:])


def _device_status(dev: Any, mapper: Any) -> tuple[str, bool] | tuple[str, bool, int]:
    """(spec, connected), with the count of input lost to bursts for a device that can lose some."""
    ok = bool(mapper.status.get(dev.spec, dev.connected))
    drops = getattr(dev, "drops", None)
    return (dev.spec, ok) if drops is None else (dev.spec, ok, int(drops))


def _keyboard_alone(devs: Sequence[Any]) -> tuple[Any, bool]:
    """The keyboard device (or None), and whether it is the only box (then the whole key map is on)."""
    kb = next((d for d in devs if d.spec.startswith("keyboard")), None)
    return kb, kb is not None and len([d for d in devs if getattr(d, "scheme", "") != "panel"]) == 1


def open_live_window(model: Any, devs: Sequence[Any]) -> Any:
    """The live face window, or None (one line says why). Opened before the show's core is made, so
    that the window, its GL context and the renderer are set up while numba's kernels are still
    loading in their thread (`warm_up_in_background`) instead of after."""
    _, keymap = _keyboard_alone(devs)
    win = _window_or_none(model, "facepuppet live", [*LIVE_HELP, *([KEYMAP_HELP] if keymap else [])])
    if win is not None:
        try:  # the normals kernel the frames call: compiled or loaded now, not at the first frame
            win.renderer.normals.interleaved(np.asarray(model.rest))
        except Exception:  # the first frame will do it (or report what is wrong)
            pass
    return win


def run_window(core: LiveCore, drain: Callable[[], list[Event]], duration: float | None, devs: Sequence[Any],
               fullscreen: bool = False, stop: StopFlag | None = None, win: Any = None,
               pictures: Sequence[Any] = (), pipelined: bool = False) -> None:
    """Ticks on the wall clock (at most 4 per frame, then the schedule re-anchors), frames at the
    window's pace; latency is measured when the frame showing an event has been swapped. `win`: a
    window from `open_live_window` (else one is opened here). `pictures`: the performer's pages'
    face feeds (puppet.panel.face.FaceFeed); while a page watches, the window's own frame is read
    back and offered to them PICTURE_HZ times a second, so the pages show the audience's pixels and
    the server draws nothing of its own. `pipelined`: each frame's CPU half made while the frame
    before still rasterises (render.window.FaceWindow.pipelined): more frames a second on a
    software rasterizer, each shown one step later; the latency counts to the swap that shows it."""
    kb, keymap = _keyboard_alone(devs)
    if win is None:
        win = open_live_window(core.face.model, devs)
    if win is None:
        run_realtime(core, drain, duration, stop=stop)
        return
    if fullscreen:
        win.toggle_fullscreen()
    win.pipelined = pipelined
    held: list[float] = []  # pipelined: the events in the frame drawn, shown by the next step's swap

    def on_key(name: str, action: str, t: float) -> None:
        if action == "press" and _common_key(win, name):
            return
        if kb is not None:
            kb.feed_key(name, action, t)  # type: ignore[arg-type]

    win.add_key_callback(on_key)
    sched = {"start": time.monotonic(), "k0": core.tick_count}
    core.clock_origin = sched["start"] - sched["k0"] * core.dt
    frame_dt = max(core.dt, 1.0 / DISPLAY_RATE)  # without vsync, frames at most at the display's rate
    max_ticks = max(4, math.ceil(4 * frame_dt / core.dt))
    limit = None if duration is None else int(round(duration * core.rate))

    def on_frame(w: Any, now: float) -> None:
        # runs right after the window polled its input and right before it draws: the ticks due
        # take the freshest input, and nothing slow (the HUD) sits between them and the frame
        if (stop is not None and stop.stopped) or (limit is not None and core.tick_count >= limit):
            w.request_close()
            return
        ran = 0
        while sched["start"] + (core.tick_count - sched["k0"]) * core.dt <= now and ran < max_ticks:
            core.tick(drain())
            ran += 1
            if limit is not None and core.tick_count >= limit:
                break
        if sched["start"] + (core.tick_count - sched["k0"]) * core.dt < now - 4 * core.dt:
            sched["start"], sched["k0"] = now, core.tick_count  # too far behind: drop wall time
            core.clock_origin = now - core.tick_count * core.dt
        w.state = core.state

    win.add_frame_callback(on_frame)
    offered = {"t": -math.inf}

    def offer(w: Any) -> None:  # drawn, not yet swapped: the pixels are the frame about to be shown
        now = time.monotonic()
        wanting = [f for f in pictures if f.wanted]
        if wanting and now - offered["t"] >= 1.0 / PICTURE_HZ:
            offered["t"] = now
            pixels = w.read_pixels()
            for f in wanting:
                f.offer(pixels, core.tick_count, now)

    if pictures:
        win.after_draw.append(offer)
    win.hud = live_hud(core, devs, keymap)
    if core.writer is not None:  # as run_realtime
        with _BelowLoop():
            core.writer.write_behind()
    try:
        with _ShowRuntime() as runtime:
            sched["start"] = time.monotonic()
            while True:
                t_frame = time.monotonic()
                shown = win.frames_shown
                if not win.step():
                    break
                if pipelined:  # this step showed the frame the step before drew
                    drawn = list(core.unpresented)
                    core.unpresented[:] = held
                    held = drawn
                if win.frames_shown > shown:
                    core.presented(time.monotonic())  # after the swap: the frame is on its way to the screen
                core.after_frame()
                runtime.after_frame()
                # the HUD for the next frame is built off the critical path (it is one frame old)
                win.hud = live_hud(core, devs, keymap)
                # without vsync (a virtual display) do not redraw faster than the tick: wait for the
                # next boundary on an absolute deadline, so the tick runs as soon as it is due
                if time.monotonic() - t_frame < 0.004:
                    nxt = sched["start"] + (core.tick_count - sched["k0"]) * core.dt
                    wait_until(max(min(nxt, time.monotonic() + core.dt), t_frame + frame_dt), stop=stop)
    finally:
        win.close()


def run_replay_window(perf: Any, start: float = 0.0, end: float | None = None, speed: float = 1.0,
                      view: str = "shaded", sound: Path | None = None) -> int:
    """Play a Performance in the window with transport keys (see REPLAY_KEYS), and the take's
    sound (a WAV on its clock) where there is an audio output."""
    from render.hud import HudInfo, active_channels

    from puppet.replay import Replayer

    win = _window_or_none(perf.face.model, "facepuppet replay", REPLAY_HELP)
    if win is None:
        raise PuppetError("no window can be opened here: use --headless or --out")
    try:
        win.renderer.view = view
    except ValueError as err:
        win.close()
        raise PuppetError(str(err)) from err
    rp = Replayer(perf)
    end_tick = perf.ticks if end is None else max(0, min(perf.ticks, int(round(end * perf.rate))))
    play = {"pos": float(start * perf.rate), "speed": speed, "paused": False, "last": time.monotonic()}

    def on_key(name: str, action: str, t: float) -> None:
        if action not in ("press", "repeat") or _common_key(win, name):
            return
        if name in ("escape", "q"):
            win.request_close()
        elif name == "space":
            play["paused"] = not play["paused"]
        elif name in ("left", "right"):
            play["pos"] += (-1 if name == "left" else 1) * perf.rate
        elif name == "up":
            play["speed"] = min(play["speed"] * 2, 16.0)
        elif name == "down":
            play["speed"] = max(play["speed"] / 2, 1 / 16)
        elif name == "home":
            play["pos"] = start * perf.rate
        elif name == "n":
            nxt = [k for k, _ in perf.markers if k > play["pos"] + 0.5]
            if nxt:
                play["pos"] = float(nxt[0])
        play["pos"] = min(max(play["pos"], 0.0), float(end_tick))

    def on_frame(w: Any, now: float) -> None:
        if not play["paused"]:
            play["pos"] = min(float(end_tick), play["pos"] + (now - play["last"]) * perf.rate * play["speed"])
        play["last"] = now
        rp.seek(int(play["pos"]))
        w.state = rp.state
        marks = [label for k, label in perf.markers if abs(k - rp.tick) < perf.rate * 0.5]
        status = "paused" if play["paused"] else ("end" if rp.tick >= end_tick else "playing")
        lines = [f"{rp.tick / perf.rate:7.2f} / {end_tick / perf.rate:.2f} s   x{play['speed']:g}   {status}"]
        lines += [f"marker: {m}" for m in marks] + [REPLAY_KEYS + "   F1 help"]
        vals = perf.values[max(0, rp.tick - 1)]
        w.hud = HudInfo(channels=active_channels(perf.face.model.channels, vals), lines=lines)
        if player is not None:
            player.sync(play["pos"] / perf.rate, play["speed"], status == "playing")

    player = None
    if sound is not None:
        from puppet.sound_out import TakeSound

        player = TakeSound(sound)
    win.add_key_callback(on_key)
    win.add_frame_callback(on_frame)
    try:
        while win.step():
            time.sleep(0.001)
    finally:
        win.close()
        if player is not None:
            player.close()
    return 0
