"""Replay: re-simulate a recording (optionally with keyframe curves layered on it) and export it.

The recording's channel values per tick go through the same Simulator from the same rest state as
the live loop did, so every tick's positions are bit-identical to the live session's. Frames for
export are sampled from ticks on an explicit frame clock: frame j of an export at `fps` with
`speed` shows the performance at t_j = from + j * speed / fps, i.e. the state after round(t_j * rate)
ticks; a recording's "chk" records (a digest of the positions every second) are verified on the way."""

from __future__ import annotations

import hashlib
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from puppet.curves import CurveLayer, CurveSet
from puppet.errors import ConfigError, PuppetError
from puppet.live import (BENDING_AS, GAZE_TISSUE_AS, JAW_AS, JAW_BENDING_AS, JAW_CONSTANTS_AS, LIDS_APART_AS, LIDS_AS,
                         MUSCLES_AS, RESPONSES_AS, SOLVE_AS, Face, load_face)
from puppet.session import Session
from safefile import quote

CHECKPOINT_TICKS = 60
MAX_FPS = 10_000.0
MAX_FRAMES = 10_000_000


def state_digest(state: Any) -> str:
    """A short digest of the positions, to check determinism between runs."""
    return hashlib.sha1(np.ascontiguousarray(state.positions).tobytes()).hexdigest()[:16]


@dataclass
class Performance:
    """What to re-simulate: a full (ticks, C) array of channel values at `rate` ticks per second."""

    face: Face
    values: np.ndarray
    rate: float
    markers: list[tuple[int, str]]
    checks: dict[int, str]
    #: ticks where the live program restarted (a crash): the face starts again from rest there
    restarts: tuple[int, ...] = ()
    #: recorded before the implicit step added the muscles as responses (no "muscles" in its
    #: header): replayed with them summed into the frame's forces, as recorded, for the same bits
    muscles_summed: bool = False
    #: the lids follow the eyes' turn (`sim.gaze_lids`); False for a take recorded before they did
    #: (no "lids" in its header), replayed with the lids still, as recorded
    lids_follow_gaze: bool = True
    #: the upper and lower lids held to the turning eye apart; False for a take recorded with them
    #: held alike (no "lid coupling" in its header), replayed so (sim.Simulator.lids_apart off)
    lids_apart: bool = True
    #: recorded with the jaw and the skin's age taken whole at each step (no "jaw" in its header):
    #: replayed that way (sim.Simulator.jaw_responses off), for the same bits
    jaw_responses: bool = True
    #: recorded with the margin bending's rest side made as the product with the turned rest shape
    #: (no "jaw bending" in its header): replayed that way (sim.Simulator.bending_turned off)
    bending_turned: bool = True
    #: recorded with the substeps solving from L and U (no "solve" in its header): replayed that way
    #: (sim.Simulator.symmetric_solve off)
    symmetric_solve: bool = True
    #: recorded with the inputs' responses read in float64 (no "responses" in its header): replayed
    #: that way (sim.Simulator.single_responses off)
    single_responses: bool = True
    #: recorded with the jaw's constants turned at each opening (no "jaw constants" in its header):
    #: replayed that way (sim.Simulator.constants_from_grid off)
    constants_from_grid: bool = True
    #: the tissue round the globe carried by the turning eye; False for a take recorded before (no
    #: "gaze tissue" in its header), replayed without it (sim.Simulator.gaze_tissue off)
    gaze_tissue: bool = True

    @property
    def ticks(self) -> int:
        return int(self.values.shape[0])

    @property
    def duration(self) -> float:
        return self.ticks / self.rate


_LOADERS: dict[str, Any] = {"load_face": load_face, "new_simulator": None}


def use_loaders(load_face: Any = None, new_simulator: Any = None) -> None:
    """How this process loads faces and makes a replay's simulator: `puppet.live.load_face` and
    `sim.Simulator(model, frame_dt)` unless replaced (a batch worker keeps both between takes,
    `puppet.batch.worker`); None restores the default."""
    from puppet import live

    _LOADERS["load_face"] = load_face or live.load_face
    _LOADERS["new_simulator"] = new_simulator


def _new_simulator(model: Any, frame_dt: float) -> Any:
    make = _LOADERS["new_simulator"]
    if make is not None:
        return make(model, frame_dt)
    import sim

    return sim.Simulator(model, frame_dt)


def face_for(session: Session | None, rig_path: str | None, face: str | None = None) -> Face:
    """The face a recording was made with: --rig, else the recorded rig path, else the recorded
    face (its --face spec and identity weights, puppet.faces), else the procedural face at the
    recorded resolution (a take from before faces were recorded); a hash mismatch is a warning
    (the motion will differ)."""
    from puppet.faces import recorded_face

    load_face = _LOADERS["load_face"]
    if session is None:
        return load_face(rig_path, face=face)
    rig = session.header.get("rig") or {}  # checked by the reader: str path, int resolution 0..2
    path = rig_path or rig.get("path")
    if not rig_path and path and not Path(path).exists():  # a --rig of the user's is checked as it loads
        raise ConfigError(f"{session.path}: recorded with rig {quote(path, 120)}, which is missing; pass --rig PATH")
    # a take recorded before a scanned head's forehead bent as its bound layer (no "bending" in its
    # header, puppet.live.BENDING_AS, and another face hash than the face has now) replays on the
    # forehead it was recorded on; other faces have no such layer
    want = rig.get("hash")

    def thin_forehead(loaded: Face) -> bool:
        layer = getattr(getattr(loaded.model, "params", None), "forehead_bending", 1.0)
        return session.header.get("bending") != BENDING_AS and layer != 1.0 and bool(want) and loaded.rig["hash"] != want

    if path:
        loaded = load_face(path)
        if thin_forehead(loaded):
            loaded = load_face(path, bound_forehead=False)
    else:
        try:
            asked: Any = face if face is not None else (recorded_face(rig) or "procedural")
            resolution = int(rig.get("resolution", 0) or 0)
            loaded = load_face(None, resolution, face=asked)
            if thin_forehead(loaded):
                loaded = load_face(None, resolution, face=asked, bound_forehead=False)
        except PuppetError as err:
            if face is not None:
                raise
            raise ConfigError(f"{session.path}: the face it records cannot be loaded: {err}; "
                              f"pass --face SPEC") from err
    if want and loaded.rig["hash"] != want:
        import sys

        print(f"puppet: warning: {session.path} was recorded with rig hash {want}, but the face loaded now "
              f"has {loaded.rig['hash']} (another rig or program version): the replay will not be "
              f"bit-identical; pass --rig with the recording's rig", file=sys.stderr)
    return loaded


def build_performance(session: Session | None, curves: CurveSet | None, rig_path: str | None = None,
                      rate: float = 60.0, face: str | None = None) -> Performance:
    """Channel values per tick from a recording and/or curves (curves layered over the recording)."""
    if session is None and curves is None:
        raise PuppetError("nothing to replay: give a recording FILE and/or --curves FILE")
    face = face_for(session, rig_path, face)
    names = [c.name for c in face.vocab.channels]
    defaults = np.array(face.vocab.defaults(), dtype=np.float64)
    markers: list[tuple[int, str]] = []
    checks: dict[int, str] = {}
    if session is not None:
        rate = session.tick_rate
        values = session.value_array(defaults, names)
        _clamp(values, face, str(session.path))
        markers = list(session.markers)
        checks = dict(session.checks)
    else:
        assert curves is not None
        n = max(1, int(np.ceil(curves.duration * rate)) + 1)
        values = np.tile(defaults, (n, 1))
    if curves is not None:
        layer = CurveLayer(curves, face.vocab)
        if session is not None and curves.duration * rate > values.shape[0]:
            extra = int(np.ceil(curves.duration * rate)) + 1 - values.shape[0]
            values = np.vstack([values, np.tile(values[-1] if len(values) else defaults, (extra, 1))])
        layered = np.array([layer.apply(values[k], k / rate) for k in range(values.shape[0])])
        if checks:  # a recording's digests hold up to the first tick the curves change
            differs = np.flatnonzero(np.any(layered != values, axis=1))
            if len(differs):
                checks = {k: v for k, v in checks.items() if k <= int(differs[0])}
        values = layered
    restarts = tuple(session.segments) if session is not None else ()
    summed = session is not None and session.header.get("muscles") != MUSCLES_AS
    follow = session is None or session.header.get("lids") == LIDS_AS
    jaw = session is None or session.header.get("jaw") == JAW_AS
    turned = session is None or session.header.get("jaw bending") == JAW_BENDING_AS
    symmetric = session is None or session.header.get("solve") == SOLVE_AS
    single = session is None or session.header.get("responses") == RESPONSES_AS
    grid = session is None or session.header.get("jaw constants") == JAW_CONSTANTS_AS
    apart = session is None or session.header.get("lid coupling") == LIDS_APART_AS
    tissue = session is None or session.header.get("gaze tissue") == GAZE_TISSUE_AS
    return Performance(face, values, rate, markers, checks, restarts, summed, follow, apart, jaw, turned, symmetric,
                       single, grid, tissue)


def _clamp(values: np.ndarray, face: Face, source: str) -> None:
    """Values read from a file are held to each channel's range (a jaw of 1e308 would throw the
    face across the room): clamped in place, with one warning naming the first."""
    lo = np.array([c.lo for c in face.vocab.channels])
    hi = np.array([c.hi for c in face.vocab.channels])
    bad = (values < lo) | (values > hi)
    if not bad.any():
        return
    import sys

    k, j = (int(x) for x in np.argwhere(bad)[0])
    c = face.vocab.channels[j]
    print(f"puppet: warning: {source}: {int(bad.sum())} channel values lie outside their channel's range "
          f"(first: {c.name} = {values[k, j]:.6g} at tick {k}, range {c.lo:g}..{c.hi:g}); clamped to it",
          file=sys.stderr)
    np.clip(values, lo, hi, out=values)


class Replayer:
    """Steps a fresh Simulator through a Performance; `seek(k)` reaches the state after k ticks,
    restoring the nearest earlier checkpoint when going back (so the window can scrub)."""

    def __init__(self, perf: Performance) -> None:
        import sim

        self.perf = perf
        self.sim = self._simulator()
        self.control = sim.FaceControl(perf.face.model)
        self.state = perf.face.model.rest_state()
        self.tick = 0
        self.checkpoints: dict[int, Any] = {0: self.state.copy()}
        self.verified = 0
        self.mismatches: list[int] = []

    def _simulator(self) -> Any:
        s = _new_simulator(self.perf.face.model, 1.0 / self.perf.rate)
        s.muscles_summed = self.perf.muscles_summed
        s.lids_follow_gaze = self.perf.lids_follow_gaze
        s.lids_apart = self.perf.lids_apart
        s.gaze_tissue = self.perf.gaze_tissue
        s.jaw_responses = self.perf.jaw_responses
        s.bending_turned = self.perf.bending_turned
        s.symmetric_solve = self.perf.symmetric_solve
        s.single_responses = self.perf.single_responses
        s.constants_from_grid = self.perf.constants_from_grid
        return s

    def step(self) -> None:
        k = self.tick
        if k >= self.perf.ticks:
            return
        if k in self.perf.restarts:  # as the restarted live program did: a fresh simulator at rest
            self.sim = self._simulator()
            self.state.assign(self.perf.face.model.rest_state())
        self.control.values[...] = self.perf.values[k]
        self.sim.step(self.state, self.control)
        self.tick = k + 1
        want = self.perf.checks.get(self.tick)
        if want is not None and self.tick not in self.checkpoints:
            if state_digest(self.state) == want:
                self.verified += 1
            else:
                self.mismatches.append(self.tick)
        if self.tick % CHECKPOINT_TICKS == 0 and self.tick not in self.checkpoints:
            self.checkpoints[self.tick] = self.state.copy()

    def seek(self, k: int) -> None:
        k = max(0, min(int(k), self.perf.ticks))
        if k < self.tick:
            base = max(t for t in self.checkpoints if t <= k)
            self.state.assign(self.checkpoints[base])
            self.tick = base
        while self.tick < k:
            self.step()


def frame_ticks(perf: Performance, fps: float, start: float = 0.0, end: float | None = None,
                speed: float = 1.0) -> list[int]:
    """The tick shown by each exported frame (see the module docstring)."""
    if not (0 < fps <= MAX_FPS and 0 < speed <= MAX_FPS):
        raise PuppetError(f"--fps and --speed must be positive, at most {MAX_FPS:g}")
    if np.isnan(start) or (end is not None and np.isnan(end)):
        raise PuppetError("--from and --to must be numbers of seconds, not nan")
    if end is not None and end < 0:
        raise PuppetError(f"--to {end:g} must be at least 0 s")
    if end is not None and start > end:
        raise PuppetError(f"--from {start:g} s is after --to {end:g} s")
    end = perf.duration if end is None else min(end, perf.duration)
    if start < 0 or start > end:
        raise PuppetError(f"--from {start:g} must lie in 0..{end:.3f} s (the end of the replay)")
    frames = (end - start) * fps / speed  # a float: a speed near 0 made it infinite (int() raised)
    if not frames <= MAX_FRAMES:
        raise PuppetError(f"{frames:.3g} frames asked ({end - start:.6g} s at {fps:g} fps, speed {speed:g}); "
                          f"at most {MAX_FRAMES}: raise --speed, lower --fps or shorten --from/--to")
    n = max(1, int(round(frames)))
    return [min(perf.ticks, int(round((start + j * speed / fps) * perf.rate))) for j in range(n)]


def iter_frames(perf: Performance, ticks: list[int],
                mismatches: list[int] | None = None) -> Iterator[tuple[int, int, Any, np.ndarray]]:
    """(frame, tick, state, values) for each requested tick, simulating forward once; the ticks
    whose state differs from the recording's checksum are added to `mismatches`."""
    rp = Replayer(perf)
    if mismatches is not None:
        rp.mismatches = mismatches
    for j, k in enumerate(ticks):
        rp.seek(k)
        vals = perf.values[k - 1] if k > 0 else perf.values[0]
        yield j, k, rp.state, vals
