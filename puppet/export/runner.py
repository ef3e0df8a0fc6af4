"""One entry point for every export, chosen by the output's suffix:

  .mp4         video (imageio-ffmpeg, H.264, any view)
  folder/      PNG frames frame_000000.png ... (a path without suffix, or an existing folder)
  .png         one still frame (at --from)
  .obj         the posed mesh at --from (as `puppet pose --out X.obj` writes it; the scanned head: its
               26,719 vertices in the scan's order)
  .pc2         point cache + a rest .obj beside it with the same vertex order (Blender Mesh Cache)
  .arkit.csv   Live Link Face-style ARKit blendshape CSV
  .csv         native channel curves
  .curves      keyframe curves text, editable, playable with `puppet replay --curves`

Every export shows a tqdm progress bar on a terminal and writes its frame rate explicitly."""

from __future__ import annotations

import os
import sys
from collections.abc import Callable, Collection
from contextlib import ExitStack
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from tqdm import tqdm

from puppet.errors import ConfigError, PuppetError
from puppet.replay import Performance, Replayer, frame_ticks, iter_frames
from safefile import atomic_dir, atomic_path, atomic_write


@dataclass
class ExportOptions:
    fps: float = 30.0
    start: float = 0.0
    end: float | None = None
    speed: float = 1.0
    view: str = "shaded"
    size: tuple[int, int] = (1280, 720)
    start_frame: float = 1.0
    parallel: bool = True  # render in other processes while this one simulates (long exports)
    workers: int | None = None  # render processes (default: one per core)
    supersample: int = 1  # samples per pixel along each axis for video and images (2 = 4 samples)
    crf: int | None = None  # H.264 constant rate factor (default puppet.export.video.DEFAULT_CRF)
    preset: str | None = None  # x264 preset (default ultrafast)
    sound: Path | None = None  # a WAV on the take's clock (puppet.audio_take): muxed into an MP4 as AAC


def kind_of(out: Path) -> str:
    name = out.name.lower()
    if name.endswith(".arkit.csv"):
        return "arkit"
    suffix = out.suffix.lower()
    kinds = {".mp4": "mp4", ".png": "png", ".pc2": "pc2", ".csv": "csv", ".curves": "curves", ".obj": "obj"}
    # a folder in the way of `x.csv` is the file's name taken, not a request for PNG frames (they
    # went into it): the write names the folder; a folder of any other name gets the frames
    if (out.is_dir() and suffix not in kinds) or suffix == "" or str(out).endswith(("/", "\\")):
        return "frames"
    if suffix not in kinds:
        raise PuppetError(f"{out}: unknown export type {suffix!r}; expected .mp4, a folder for PNG frames, "
                          ".png, .obj, .pc2, .csv, .arkit.csv or .curves")
    return kinds[suffix]


def written_files(out: Path) -> list[Path]:
    """The files an export to `out` writes: a PC2's rest mesh beside it too."""
    return [out, out.with_suffix(".obj")] if kind_of(out) == "pc2" else [out]


def unused_output(out: Path, claimed: Collection[Path] = ()) -> Path:
    """`out` if none of the files its export writes exists or is `claimed` (by an export not yet
    written), else the first free `STEM-2.SUFFIX`, `STEM-3.SUFFIX`, ...: the page's exports never
    replace a file (`take.arkit.csv` -> `take-2.arkit.csv`)."""
    name = out.name
    suffix = ".arkit.csv" if name.lower().endswith(".arkit.csv") and len(name) > 10 else out.suffix
    stem = name[: len(name) - len(suffix)] if suffix else name
    taken = {Path(c) for c in claimed}
    for n in range(1, 10_000):
        path = out if n == 1 else out.with_name(f"{stem}-{n}{suffix}")
        if not any(os.path.lexists(p) or p in taken for p in written_files(path)):
            return path
    raise PuppetError(f"{out}: 10,000 exports of that name exist already; move some away")


def _bar(total: int, what: str) -> tqdm:
    # a bar on a terminal only: in a log or a pipe it would be a line of carriage returns
    return tqdm(total=total, desc=what, unit="frame", file=sys.stderr, dynamic_ncols=True, leave=False, disable=None)


def export(perf: Performance, out: str | Path, opts: ExportOptions) -> str:
    """Write `perf` to `out`; returns a one-line summary for the user. Every export is written
    beside `out` and moved into place when complete: a failed export leaves the old file as it was."""
    out = Path(out)
    kind = kind_of(out)
    if kind != "frames" and not out.parent.exists():
        raise ConfigError(f"{out}: folder {out.parent} does not exist")
    if kind in ("mp4", "frames", "png"):
        try:
            from render.renderer import VIEWS
        except ImportError as err:
            raise PuppetError(f"video and image export need the renderer: {err}") from err
        if opts.view not in VIEWS:
            raise PuppetError(f"unknown view {opts.view!r}; choose one of {', '.join(VIEWS)}")
    ticks = frame_ticks(perf, opts.fps, opts.start, opts.end, opts.speed)
    if kind in ("png", "obj"):
        ticks = ticks[:1]
    names = [c.name for c in perf.face.vocab.channels]
    if kind == "curves":
        from puppet.curves import curves_from_values

        a = ticks[0]
        b = max(ticks[-1], a + 1)
        with _bar(1, "curves") as bar:
            text = curves_from_values(perf.values[a:b], names, perf.rate, perf.face.vocab)
            bar.update(1)
        try:
            with atomic_write(out) as fh:
                fh.write(text)
        except OSError as err:
            raise ConfigError(f"{out}: cannot write the curves: {err.strerror or err}") from err
        return f"wrote keyframe curves for ticks {a}..{b} to {out}"
    if kind in ("csv", "arkit"):
        return _export_csv(perf, out, kind, ticks, names, opts)
    mismatches: list[int] = []
    if kind == "obj":
        done = _export_obj(perf, out, ticks, mismatches)
    elif kind == "pc2":
        done = _export_pc2(perf, out, ticks, opts, mismatches)
    else:
        done = _export_images(perf, out, kind, ticks, opts, mismatches)
    warn_diverged(out, mismatches)
    return done


def warn_diverged(out: Path, mismatches: list[int]) -> None:
    """One line on stderr when the simulation behind an export left the recording's checksums: the
    file shows this program's simulation of the take, not the show's."""
    if mismatches:
        print(f"puppet: warning: {out}: the simulation diverged from the recording at tick {mismatches[0]} "
              "(a different rig, program or numpy build?): it shows this program's simulation of the take, "
              "not the show's", file=sys.stderr)


def _export_csv(perf: Performance, out: Path, kind: str, ticks: list[int], names: list[str],
                opts: ExportOptions) -> str:
    from puppet.export.arkit import ArkitCsvWriter
    from puppet.export.channels_csv import ChannelCsvWriter

    with atomic_path(out) as tmp:
        w: Any = ArkitCsvWriter(tmp, names, opts.fps) if kind == "arkit" else ChannelCsvWriter(tmp, names)
        try:
            with _bar(len(ticks), out.name) as bar:
                for j, k in enumerate(ticks):
                    vals = perf.values[max(0, k - 1)]
                    if kind == "arkit":
                        w.add(j, vals)
                    else:
                        w.add(j, j / opts.fps, k, vals)
                    bar.update(1)
        finally:
            w.close()
    return f"wrote {len(ticks)} frames at {opts.fps:g} fps to {out}"


REST_OBJ_MARK = b"# facepuppet rest pose"


def _keep_foreign_obj(obj: Path, out: Path) -> None:
    """The rest mesh beside a PC2 replaces only a rest mesh an export wrote (its first line says
    so), never the user's own OBJ of that name."""
    try:
        with open(obj, "rb") as fh:
            head = fh.read(len(REST_OBJ_MARK))
    except FileNotFoundError:
        return
    except OSError as err:
        raise PuppetError(f"{obj}: cannot check the mesh beside {out.name}: {err.strerror}") from err
    if head != REST_OBJ_MARK:
        raise PuppetError(f"{obj}: a mesh a PC2 export did not write; {out.name}'s rest mesh would replace it: "
                          "move it or give --out another name")


def _pc2_sink(perf: Performance, out: Path, opts: ExportOptions, stack: ExitStack) -> Callable[[Any], None]:
    """Opens `out` (and its rest .obj beside it) for writing on `stack`; returns the per-frame add."""
    from puppet.export.pc2 import PC2Writer, write_obj
    from puppet.export.scan import posed, scan_dressing, write_scan_obj
    from sim.face.turn import state_turn, turn_head, turn_weights

    model = perf.face.model
    obj = out.with_suffix(".obj")
    _keep_foreign_obj(obj, out)
    dressing = scan_dressing(model)  # the scanned head: the scan's own vertices and faces
    rest = model.rest if dressing is None else dressing.rest
    obj_tmp = stack.enter_context(atomic_path(obj))
    pc2_tmp = stack.enter_context(atomic_path(out))
    note = (f"point cache: {out.name}, {opts.fps:g} fps, starts at frame {opts.start_frame:g}")
    if dressing is None:
        write_obj(obj_tmp, rest, model.triangles,
                  f"facepuppet rest pose, {len(rest)} vertices in simulation order (cm, +Y up)\n{note}")
    else:
        write_scan_obj(obj_tmp, rest, f"facepuppet rest pose of the scanned head (ICT FaceKit topology), "
                       f"{len(rest)} vertices in the scan's order (cm, +Y up)\n{note}")
    w = PC2Writer(pc2_tmp, len(rest), start_frame=opts.start_frame, sampling=1.0)
    stack.callback(w.close)
    weights = turn_weights(rest)

    def add(state: Any) -> None:
        if dressing is None:  # as drawn: the head turned on the neck
            w.add(turn_head(state.surface, weights, *state_turn(state)))
        else:
            w.add(posed(dressing, state))

    return add


def _pc2_summary(out: Path, n: int, opts: ExportOptions) -> str:
    return (f"wrote {n} samples at {opts.fps:g} fps (start frame {opts.start_frame:g}) to {out} "
            f"and the rest mesh to {out.with_suffix('.obj')}; in Blender: scene at {opts.fps:g} fps, Mesh Cache "
            "modifier Time Mode Frame, Frame Start 1, Forward -Z, Up +Y (docs/live.md)")


def _obj_vertices(model: Any) -> str:
    """What an OBJ of the face holds, as `puppet pose` says it: the scanned head's OBJ is the whole
    scan (its vertices in its order) posed from the simulated skin."""
    from puppet.export.scan import scan_dressing

    dressing = scan_dressing(model)
    if dressing is None:
        return f"{len(model.rest)} vertices"
    return f"the scan's {len(dressing.rest)} vertices, posed from {len(model.rest)} simulated"


def _export_obj(perf: Performance, out: Path, ticks: list[int], mismatches: list[int]) -> str:
    """The posed mesh at the first of `ticks` (--from), written as `puppet pose` writes an OBJ.
    (`--out take.obj` was refused: an OBJ came only as the rest mesh beside a PC2.)"""
    from puppet.cmd_pose import write_pose

    for _, k, state, _ in iter_frames(perf, ticks, mismatches):
        try:
            write_pose(perf.face.model, state, out)
        except OSError as err:
            raise ConfigError(f"{out}: cannot write the mesh: {err.strerror or err}") from err
        return f"wrote the posed mesh at {k / perf.rate:.3f} s ({_obj_vertices(perf.face.model)}) to {out}"
    raise PuppetError(f"{out}: no frame to write")


def _export_pc2(perf: Performance, out: Path, ticks: list[int], opts: ExportOptions,
                mismatches: list[int] | None = None) -> str:
    with ExitStack() as stack:
        add = _pc2_sink(perf, out, opts, stack)
        with _bar(len(ticks), out.name) as bar:
            for _, _, state, _ in iter_frames(perf, ticks, mismatches):
                add(state)
                bar.update(1)
    return _pc2_summary(out, len(ticks), opts)


def export_together(perf: Performance, outputs: list[tuple[Path, ExportOptions]]) -> list[str]:
    """Several exports of one performance, simulated once: each PC2 and MP4 output gets the state
    of every frame it samples from one pass of the simulation (each at its own frame rate), written
    exactly as `export` writes it alone (MP4 rendered in this process, `parallel` ignored); the other
    kinds need no simulation and go through `export`. Returns the summaries in the given order."""
    from puppet.export.video import DEFAULT_CRF, DEFAULT_PRESET, FrameSink

    done: dict[int, str] = {}
    shared: list[tuple[int, Path, str, ExportOptions]] = []
    for i, (out, opts) in enumerate(outputs):
        kind = kind_of(Path(out))
        if kind in ("pc2", "mp4") and opts.sound is None:
            shared.append((i, Path(out), kind, opts))
        else:
            done[i] = export(perf, out, opts)
    if len(shared) == 1:
        i, out, _, opts = shared[0]
        done[i] = export(perf, out, opts)
    elif shared:
        with ExitStack() as stack:
            plan: list[tuple[int, int, Callable[[Any], None]]] = []  # (tick, output, frame's add)
            sinks: list[FrameSink] = []
            for i, out, kind, opts in shared:
                if not out.parent.exists():
                    raise ConfigError(f"{out}: folder {out.parent} does not exist")
                ticks = frame_ticks(perf, opts.fps, opts.start, opts.end, opts.speed)
                if kind == "pc2":
                    add = _pc2_sink(perf, out, opts, stack)
                    done[i] = _pc2_summary(out, len(ticks), opts)
                    plan += [(k, i, add) for k in ticks]
                    continue
                crf = DEFAULT_CRF if opts.crf is None else opts.crf
                if not (1 <= opts.supersample <= 4 and 0 <= crf <= 51):
                    raise PuppetError(f"--supersample must be 1 to 4 and --crf 0 to 51 (got {opts.supersample}, "
                                      f"{crf})")
                _check_drawn_side(opts)
                target = stack.enter_context(atomic_path(out))
                sink = FrameSink(perf.face.model, target, "mp4", opts.fps, opts.size, opts.view, opts.supersample,
                                 opts.preset or DEFAULT_PRESET, crf)
                stack.push(sink.exit)
                sinks.append(sink)
                frames = iter(range(len(ticks)))
                plan += [(k, i, lambda st, s=sink, f=frames: s.add(next(f), st)) for k in ticks]
                done[i] = (f"wrote {len(ticks)} frames at {opts.fps:g} fps ({opts.size[0]}x{opts.size[1]}, "
                           f"view {opts.view}) to {out}")
            plan.sort(key=lambda p: (p[0], p[1]))  # stable: each output's frames stay in order
            rp = Replayer(perf)
            for k, _, add in plan:
                rp.seek(k)
                add(rp.state)
            for sink in sinks:
                sink.finish()
        warn_diverged(Path(", ".join(str(out) for _, out, _, _ in shared)), rp.mismatches)
    return [done[i] for i in range(len(outputs))]


def _check_drawn_side(opts: ExportOptions) -> None:
    from render.offscreen import MAX_DRAWN_SIDE

    side = max(opts.size) * opts.supersample
    if side > MAX_DRAWN_SIDE:
        raise PuppetError(f"--size {opts.size[0]}x{opts.size[1]} with --supersample {opts.supersample} draws {side} "
                          f"pixels a side, more than {MAX_DRAWN_SIDE}: lower one of them")


def _export_images(perf: Performance, out: Path, kind: str, ticks: list[int], opts: ExportOptions,
                   mismatches: list[int] | None = None) -> str:
    from puppet.export.video import DEFAULT_CRF, DEFAULT_PRESET, PARALLEL_MIN_FRAMES, render_parallel, render_serial

    if not 1 <= opts.supersample <= 4:
        raise PuppetError(f"--supersample must be 1 to 4, got {opts.supersample}")
    _check_drawn_side(opts)
    crf = DEFAULT_CRF if opts.crf is None else opts.crf
    if not 0 <= crf <= 51:
        raise PuppetError(f"--crf must be 0 to 51, got {crf}")
    enc = {"supersample": opts.supersample, "preset": opts.preset or DEFAULT_PRESET, "crf": crf}
    sound = opts.sound if kind == "mp4" else None
    if sound is not None:  # a damaged WAV is named before anything is drawn
        from devices.audio.wavfile import read_wav

        read_wav(sound)
    frames = ((j, state) for j, _, state, _ in iter_frames(perf, ticks, mismatches))
    place = atomic_dir(out, stale="frame_*.png") if kind == "frames" else atomic_path(out)
    with place as target, _bar(len(ticks), out.name or str(out)) as bar:
        if len(ticks) >= PARALLEL_MIN_FRAMES and opts.parallel:
            render_parallel(perf.face.model, target, kind, opts.fps, opts.size, opts.view, frames, bar.update,
                            workers=opts.workers, **enc)
        else:
            render_serial(perf.face.model, target, kind, opts.fps, opts.size, opts.view, frames, bar.update, **enc)
        if sound is not None:  # muxed before the rename: a failure keeps the user's old file
            from puppet.export.sound import mux_sound

            mux_sound(target, sound, opts.start, opts.speed, len(ticks) / opts.fps, shown=out)
    if kind == "png":
        return f"wrote a {opts.size[0]}x{opts.size[1]} still to {out}"
    if sound is not None:
        return (f"wrote {len(ticks)} frames at {opts.fps:g} fps ({opts.size[0]}x{opts.size[1]}, view {opts.view}) "
                f"with the take's sound ({opts.sound.name}, AAC) to {out}")
    return f"wrote {len(ticks)} frames at {opts.fps:g} fps ({opts.size[0]}x{opts.size[1]}, view {opts.view}) to {out}"
