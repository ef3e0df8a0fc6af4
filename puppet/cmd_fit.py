"""`puppet fit`: tracked motion -> the channels that explain it, written as a take or curves."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

OUT_KINDS = {".jsonl": "take", ".curves": "curves"}
#: --smooth and --sparsity: relative to the basis' mean column energy (the defaults 0.02, 0.004)
MAX_WEIGHT = 1000.0


def register(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = subparsers.add_parser(
        "fit",
        help="fit channel activations to tracked motion (landmark CSV, C3D, PC2, ARKit CSV) or a voice (WAV) -> take",
        description="Analysis by synthesis: per frame, the channel activations (0..max) that best explain "
        "the tracked skin motion, on a displacement basis built by the simulator, warm-started, smoothed "
        "over time and re-linearised where channels interact. INPUT: a landmark CSV (header time, "
        "NAME_x,NAME_y,NAME_z...), a C3D file, a PC2 point cache of the rig (+ .obj beside it), or a Live "
        "Link Face / ARKit blendshape CSV (converted through the ARKit mapping, then re-simulated), or a WAV of a "
        "voice (the live audio:// analysis, offline, through the voice map). "
        "--out TAKE.jsonl replays with `puppet replay`; --out FILE.curves with `puppet replay --curves`. "
        "See docs/fit.md.",
    )
    p.add_argument("input", metavar="INPUT", help="the capture")
    p.add_argument("--rig", metavar="R", help="rig file to fit (default: the built-in face)")
    p.add_argument("--face", metavar="SPEC", default=None,
                   help="the face: ict, ict?identity=SEED, procedural or a saved identity's NAME")
    p.add_argument("--out", required=True, metavar="TAKE.jsonl|CURVES", help="the take or curves to write")
    p.add_argument("--map", metavar="CORR.json",
                   help="correspondence file: input point/marker name -> rig landmark (MediaPipe, 68-point, "
                   "C3D labels); 'mediapipe' and 'ibug68' name the shipped ones")
    p.add_argument("--report", metavar="FILE.csv", help="per-frame report: residual mm, active channels, condition")
    p.add_argument("--neutral", default="auto", metavar="FRAME|rig",
                   help="the frame showing the face at rest (default 0), or 'rig' to compare with the rig's own "
                   "rest (the default for PC2 caches of the rig)")
    p.add_argument("--fps", type=float, metavar="N", help="frame rate of PC2 samples / ARKit timecodes (default 60)")
    p.add_argument("--rate", type=float, default=60.0, metavar="HZ", help="tick rate of the written take (default 60)")
    p.add_argument("--age", type=float, metavar="YEARS", help="age channel of the written take (wrinkles)")
    p.add_argument("--smooth", type=float, metavar="X", help="temporal smoothing weight (default 0.02)")
    p.add_argument("--sparsity", type=float, metavar="X", help="L1 weight keeping idle channels at 0 (default 0.004)")
    p.add_argument("--no-relinearise", action="store_true", help="linear fit only (no settles during the fit)")
    p.add_argument("--voice-profile", metavar="FILE",
                   help="INPUT.wav: the voice profile from `puppet learn --device audio://NAME --profile FILE`")
    p.set_defaults(func=run)


def _neutral(text: str) -> int | None | str:
    from puppet.errors import PuppetError

    if text in ("auto", "rig"):
        return None if text == "rig" else "auto"
    try:
        k = int(text)
    except ValueError:
        raise PuppetError(f"--neutral takes a frame number or 'rig', got {text!r}") from None
    if k < 0:
        raise PuppetError("--neutral frame must be >= 0")
    return k


def _check_out(out: Path) -> str:
    from puppet.errors import PuppetError

    kind = OUT_KINDS.get(out.suffix.lower())
    if kind is None:
        raise PuppetError(f"{out}: --out must end in .jsonl (a take) or .curves (keyframe curves)")
    if not out.parent.resolve().is_dir():
        raise PuppetError(f"{out}: the folder {out.parent} does not exist")
    return kind


def summary(result: object, cap: object) -> list[str]:
    """The report's lines for the terminal."""
    import numpy as np

    r = result
    res = np.array([f.residual_mm for f in r.reports])  # type: ignore[attr-defined]
    mis = np.array([f.misfit for f in r.reports])  # type: ignore[attr-defined]
    lines = [f"fitted {len(res)} frames on {len(r.vertices)} points "  # type: ignore[attr-defined]
             f"(basis condition number {r.condition:.0f} at these points)"]  # type: ignore[attr-defined]
    if r.neutral is not None:  # type: ignore[attr-defined]
        t = r.neutral  # type: ignore[attr-defined]
        lines.append(f"neutral frame onto the rig: scale {t.scale:.4g}, rotation {t.angle_degrees:.2f} deg, "
                     f"translation {np.array2string(t.translation, precision=3)} cm; shape difference "
                     f"{r.neutral_rms_mm:.2f} mm RMS")  # type: ignore[attr-defined]
    scales = np.array([f.scale for f in r.reports])  # type: ignore[attr-defined]
    rots = np.array([f.rotation_degrees for f in r.reports])  # type: ignore[attr-defined]
    lines.append(f"head motion removed: scale {scales.min():.3f}..{scales.max():.3f} of the neutral, "
                 f"rotation up to {rots.max():.2f} deg")
    lines.append(f"residual {np.median(res):.2f} mm median, {np.percentile(res, 95):.2f} mm p95, {res.max():.2f} mm max; "
                 f"misfit {np.median(mis) * 100:.0f} % median")
    relin = sum(f.relinearised for f in r.reports)  # type: ignore[attr-defined]
    lines.append(f"re-linearised {relin} frames ({r.settles} settles in all)")  # type: ignore[attr-defined]
    acts = r.activations  # type: ignore[attr-defined]
    used = [(c, float(acts[:, j].max()), float(np.mean(acts[:, j] > 0.05)))
            for j, c in enumerate(r.channels) if acts[:, j].max() > 0.05]  # type: ignore[attr-defined]
    used.sort(key=lambda u: -u[1])
    if used:
        lines.append("active: " + ", ".join(f"{c} (max {m:.2f}, {f * 100:.0f} % of frames)" for c, m, f in used[:10])
                     + (f" and {len(used) - 10} more" if len(used) > 10 else ""))
    else:
        lines.append("active: none (no motion the channels explain)")
    seen = len(r.channels) - len(r.invisible)  # type: ignore[attr-defined]
    if 3 * len(r.vertices) < seen:  # type: ignore[attr-defined]
        lines.append(f"underdetermined: {seen} channels move these points but only {3 * len(r.vertices)} "  # type: ignore[attr-defined]
                     "coordinates are observed; add points for a unique fit")
    if r.invisible:  # type: ignore[attr-defined]
        lines.append(f"{len(r.invisible)} channels move none of these points and stay at 0: "  # type: ignore[attr-defined]
                     + ", ".join(r.invisible[:8]) + (" ..." if len(r.invisible) > 8 else ""))  # type: ignore[attr-defined]
    for note in getattr(cap, "notes", []):
        lines.append(note)
    return lines


def _check_report(report: Path, args: argparse.Namespace, out: Path) -> None:
    """The report is written last, over whatever it names: never the capture (nor the OBJ beside
    a point cache, nor the --map file) and never the take just written."""
    from puppet.errors import PuppetError

    inp = Path(args.input)
    kept = [inp, inp.with_suffix(".obj")] if inp.suffix.lower() == ".pc2" else [inp]
    if args.map and Path(args.map).suffix:
        kept.append(Path(args.map))
    for other in (*kept, out):
        if report.resolve() == other.resolve():
            what = "the take --out writes" if other is out else "a file this fit reads"
            raise PuppetError(f"--report {report}: that is {what} ({other}); name another file for the report")


#: the options of the fit proper (points onto the displacement basis): a Live Link / ARKit CSV is
#: converted through the ARKit map and a WAV analysed as a voice, neither fitted
FIT_OPTIONS = (("report", "report"), ("map", "map"), ("smooth", "smooth"), ("sparsity", "sparsity"),
               ("no_relinearise", "no-relinearise"))


def _check_options_for_input(inp: Path, args: argparse.Namespace) -> None:
    """Options the input's path does not use are refused before the face loads: they were ignored
    without a word (`--report` wrote no report, `--age` left a voice's take at the default age)."""
    from puppet.capture import is_arkit_csv
    from puppet.errors import PuppetError
    from safefile import not_a_file

    if inp.suffix.lower() == ".wav":
        what, unused = "a voice is analysed, not fitted", [*FIT_OPTIONS, ("age", "age"), ("fps", "fps")]
    else:
        if getattr(args, "voice_profile", None):
            raise PuppetError(f"--voice-profile: {inp} is not a voice (a .wav); leave out --voice-profile")
        if not (not_a_file(inp, "capture file") is None and is_arkit_csv(inp)):
            return  # points: every option applies
        what, unused = "a Live Link / ARKit CSV is converted through the ARKit map, not fitted", list(FIT_OPTIONS)
    unused.append(("neutral", "neutral"))
    for attr, opt in unused:
        if getattr(args, attr, None) not in (None, False, "auto"):
            why = ", so there is no per-frame residual to report" if opt == "report" else ""
            raise PuppetError(f"--{opt}: {inp}: {what}{why}; leave out --{opt}")


def _check_length(seconds: float, rate: float, channels: int) -> None:
    """The take fits what a replay holds (`MAX_CELLS` tick x channel values)."""
    from puppet.errors import PuppetError
    from puppet.session_reader import MAX_CELLS

    ticks = seconds * rate + 1.0  # a float: a PC2's sampling field may spread its samples over 1e30 s
    if not ticks * channels <= MAX_CELLS:
        raise PuppetError(f"--rate {rate:g} over the capture's {seconds:.4g} s makes {ticks:.4g} ticks of {channels} "
                          f"channels, more than a take holds ({MAX_CELLS} values): lower --rate or cut the capture")


def run(args: argparse.Namespace) -> int:
    from puppet.capture import ChannelCapture, read_capture
    from puppet.capture.take import full_values, resample, write_curves, write_report, write_take
    from puppet.errors import PuppetError
    from puppet.live import load_face

    out = Path(args.out)
    kind = _check_out(out)
    if args.report:
        _check_report(Path(args.report), args, out)
    neutral = _neutral(args.neutral)
    _check_options_for_input(Path(args.input), args)
    for name in ("smooth", "sparsity"):
        # nan or inf made the solver's Cholesky factor a ValueError traceback, a negative weight a
        # LinAlgError (smooth) or every channel driven to its maximum (sparsity)
        value = getattr(args, name)
        if value is not None and not 0.0 <= value <= MAX_WEIGHT:
            raise PuppetError(f"--{name} {value:g}: expected a weight 0..{MAX_WEIGHT:g}")
    if args.fps is not None and not args.fps > 0:
        raise PuppetError("--fps must be positive")
    from puppet.session_reader import MAX_RATE, MIN_RATE

    if not MIN_RATE <= args.rate <= MAX_RATE:
        # a take's reader holds its tick rate to this range: --rate 20000 wrote a take replay refused,
        # and --rate 1e9 filled the memory with 2e9 ticks until the kernel killed the process
        raise PuppetError(f"--rate {args.rate:g}: expected {MIN_RATE:g}..{MAX_RATE:g} ticks a second (a take's range)")
    suffix = Path(args.input).suffix.lower()
    if Path(args.input).is_file() and suffix not in (".csv", ".c3d", ".pc2", ".wav"):
        # said after the face had loaded, and without the voice: `fit speech.mp3` was told to bring
        # a .csv, .c3d or .pc2
        raise PuppetError(f"{args.input}: unknown capture type {suffix!r}; expected a landmark or ARKit .csv, "
                          ".c3d, .pc2, or a voice's .wav")
    face = load_face(args.rig, face=args.face)
    if suffix == ".wav":  # a voice: the live audio analysis, offline
        if kind != "take":
            raise PuppetError(f"{out}: a voice is fitted into a take: --out must end in .jsonl")
        from puppet.capture.voice import voice_take

        for line in voice_take(args.input, face, out, args.rate, getattr(args, "voice_profile", None)):
            print(f"puppet: {line}")
        return 0
    extra = {}
    if args.age is not None:
        if not 0 <= args.age <= 120:
            raise PuppetError("--age takes years in 0..120")
        extra["age"] = float(args.age)
    cap = read_capture(args.input, face, args.map, args.fps)
    _check_length(float(cap.times[-1] - cap.times[0]), args.rate, len(face.vocab.channels))
    if isinstance(cap, ChannelCapture):
        values = full_values(face, cap.channels, cap.values, extra)
        lines = [f"converted {len(cap.times)} blendshape frames ({cap.times[-1]:.2f} s) through the inverted "
                 "ARKit mapping; the take re-simulates them on the physical face", *cap.notes]
        reports = None
    else:
        from puppet.capture.fitting import face_basis, fit_points
        from sim.fit.solve import FitOptions

        opts = FitOptions()
        if args.smooth is not None:
            opts.smooth = args.smooth
        if args.sparsity is not None:
            opts.sparsity = args.sparsity
        if args.no_relinearise:
            opts.relinearise = None
        if isinstance(neutral, int) and neutral >= len(cap.times):
            raise PuppetError(f"--neutral {neutral}: the capture has {len(cap.times)} frames")
        settler, basis, _ = face_basis(face)
        result = fit_points(cap, settler, basis, opts, neutral)
        values = full_values(face, result.channels, result.activations, extra)
        lines = summary(result, cap)
        reports = result.reports
    ticks = resample(cap.times, values, args.rate)
    source = {"input": str(Path(args.input).resolve()), "kind": "fit" if reports is not None else "arkit"}
    if kind == "take":
        write_take(out, face, ticks, args.rate, source)
    else:
        write_curves(out, face, ticks, args.rate)
    if args.report and reports is not None:
        write_report(Path(args.report), reports)
    for line in lines:
        print(f"puppet: {line}")
    what = "a take" if kind == "take" else "keyframe curves"
    print(f"puppet: wrote {what} of {len(ticks)} ticks ({len(ticks) / args.rate:.2f} s at {args.rate:g} Hz) "
          f"to {out}" + (f"; per-frame report in {args.report}" if args.report and reports is not None else ""))
    sys.stdout.flush()
    return 0
