"""How well `puppet fit` and `puppet recognize` recover what made the motion, without the
"inverse crime": the basis is the default face at resolution 0 (RK2), the data never is.

    .venv/bin/python benchmarks/fit.py [--takes 30] [--sources res1 implicit head] [--skip-timing]

Sources of data:
  res1      the default face at resolution 1 (about 2 700 vertices; `auto` runs it with the implicit
            integrator), observed at the res-1 vertex nearest each chosen res-0 vertex
  implicit  resolution 0 with the implicit integrator (same mesh, other integrator)
  head      the default rig transferred (sim.face.transfer) onto another head: the res-1 mesh stretched
            by 1.12 / 0.93 / 1.05 in x / y / z, observed at the points matching the res-0 ones
Points: all free res-0 vertices, 68 (the 32 rig landmarks + 36 random free vertices), 20 (20
landmarks). Noise: Gaussian, sigma 0 / 0.1 / 0.5 mm per coordinate, independent per frame, on
the neutral frame too. Each sample is a short track: 5 neutral frames then the pose held for 5
frames; the fit's value is the middle pose frame's.
Random takes: 1-4 muscle/jaw channels at U(0.2, 1.0) (seeded). Metrics: activation MAE over all
the basis's channels (34: the muscles and the jaw), active-set precision / recall (threshold 0.1), residual (RMS per point, mm).
Recognition: the 7 presets at weights 0.3 / 0.5 / 0.7 / 1.0 plus 4 neutral samples, by
displacement templates and by fitted activations (scores averaged over the held frames).
Timing: a 60 s take at 60 fps (res-1 face simulated with the implicit integrator, presets
fading in and out), 68 points, 0.1 mm noise, fitted with the default options (re-linearisation
on), CPU time of this process with BLAS held to one thread.
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

NOISES_MM = (0.0, 0.1, 0.5)
POINTS = ("all", "68", "20")
INTENSITIES = (0.3, 0.5, 0.7, 1.0)
HOLD = 5


def _source(name: str, model0):  # type: ignore[no-untyped-def]
    """(settler of the data face, function res-0 vertex indices -> data vertex indices)."""
    import sim.face
    from scipy.spatial import cKDTree
    from sim.fit.align import similarity
    from sim.fit.basis import Settler

    if name == "implicit":
        return Settler(model0, method="implicit"), lambda v: np.asarray(v)
    if name == "res1":
        model = sim.face.default_model(1)
    elif name == "head":
        from sim.face.builder import build_face_mesh
        from sim.face import default_rig
        from sim.face.transfer import from_arrays, parse_landmarks, transfer_rig

        target = build_face_mesh(1)
        head = from_arrays(target.vertices * np.array([1.12, 0.93, 1.05]), target.triangles, "head.obj")
        lms = parse_landmarks({k: int(i) for k, i in target.landmarks.items()}, "head.json")
        model = sim.compile_model(transfer_rig(default_rig(0), head, lms, name="head").rig)
    else:
        raise SystemExit(f"unknown source {name!r}")
    names = sorted(model0.mesh.landmarks)
    a = np.array([model0.rest[model0.mesh.landmarks[n]] for n in names])
    b = np.array([model.rest[model.mesh.landmarks[n]] for n in names])
    t = similarity(a, b)
    tree = cKDTree(model.rest)
    lm0 = {int(v): n for n, v in model0.mesh.landmarks.items()}

    def near(verts: np.ndarray) -> np.ndarray:
        out = tree.query(t.apply(model0.rest[verts]))[1]
        for i, v in enumerate(verts):
            if int(v) in lm0:
                out[i] = model.mesh.landmarks[lm0[int(v)]]
        return out

    return Settler(model), near


def _point_sets(model0) -> dict[str, np.ndarray]:  # type: ignore[no-untyped-def]
    rng = np.random.default_rng(68)
    free = np.flatnonzero(~model0.held)
    lms = np.array(sorted(model0.mesh.landmarks.values()))
    others = np.setdiff1d(free, lms)
    twenty = np.random.default_rng(20).choice(lms, 20, replace=False)
    return {"all": free, "68": np.concatenate([lms, rng.choice(others, 36, replace=False)]), "20": np.sort(twenty)}


def _truths(n: int, channels: tuple[str, ...]) -> list[dict[str, float]]:
    rng = np.random.default_rng(15)
    out = []
    for _ in range(n):
        k = int(rng.integers(1, 5))
        idx = rng.choice(len(channels), k, replace=False)
        out.append({channels[i]: float(rng.uniform(0.2, 1.0)) for i in idx})
    return out


def _track(rest: np.ndarray, pose: np.ndarray, sigma_cm: float, rng: np.random.Generator) -> np.ndarray:
    frames = np.array([rest] * HOLD + [pose] * HOLD)
    return frames + rng.normal(0.0, sigma_cm, frames.shape) if sigma_cm > 0 else frames


def _fit(basis, settler, opts, pts: np.ndarray, verts: np.ndarray):  # type: ignore[no-untyped-def]
    from sim.fit.solve import Fitter, Track

    return Fitter(basis, settler, opts).fit(Track(np.arange(len(pts)) / 60.0, pts, verts, 0))


def _table(head: list[str], rows: list[list[str]]) -> str:
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(lines)


def accuracy(sources, basis, settler, tpl, sets, n_takes: int, model0) -> None:  # type: ignore[no-untyped-def]
    from sim.fit.basis import preset_values
    from sim.fit.recognize import NEUTRAL, activation_scores, template_scores
    from sim.fit.solve import FitOptions

    chans = basis.channels
    truths = _truths(n_takes, chans)
    labels = [*tpl.names, NEUTRAL]
    fit_rows, rec_rows, per_channel, confusions = [], [], {}, {}
    lin = FitOptions(relinearise=None)
    for src in sources:
        t0 = time.process_time()
        data, near = _source(src, model0)
        poses = [data.pose(data.values_for(t)) for t in truths]
        presets = [(n, w, data.pose(data.values_for(preset_values(n, w)))) for n in tpl.names for w in INTENSITIES]
        print(f"# {src}: {len(poses) + len(presets)} poses settled in {time.process_time() - t0:.0f} s CPU",
              file=sys.stderr)
        for pname, verts in sets.items():
            nv = near(verts)
            for noise in NOISES_MM:
                rng = np.random.default_rng(int(noise * 100) + len(verts))
                err, tp, fp, fn, res = [], 0, 0, 0, []
                chan_err = np.zeros(len(chans))
                for truth, pose in zip(truths, poses):
                    r = _fit(basis, None, lin, _track(data.rest[nv], pose[nv], noise / 10, rng), verts)
                    a = r.activations[HOLD + HOLD // 2]
                    want = np.array([truth.get(c, 0.0) for c in chans])
                    err.append(np.abs(a - want).mean())
                    chan_err += np.abs(a - want)
                    on, t_on = a > 0.1, want > 0.1
                    tp += int(np.sum(on & t_on))
                    fp += int(np.sum(on & ~t_on))
                    fn += int(np.sum(~on & t_on))
                    res.append(r.reports[HOLD + HOLD // 2].residual_mm)
                per_channel[(src, pname, noise)] = chan_err / len(truths)
                fit_rows.append([src, pname, f"{noise:g}", f"{np.mean(err):.3f}", f"{np.max(err):.3f}",
                                 f"{tp / max(1, tp + fp):.2f}", f"{tp / max(1, tp + fn):.2f}", f"{np.median(res):.2f}"])
                samples = [(NEUTRAL, 0.0, data.rest)] * 4 + presets
                conf = {"templates": {}, "activations": {}}
                for truth_name, w, pose in samples:
                    track = _track(data.rest[nv], pose[nv], noise / 10, rng)
                    r = _fit(basis, None, lin, track, verts)
                    held = slice(HOLD, 2 * HOLD)
                    ts = template_scores(r.displacements[held], tpl, verts).mean(axis=0)
                    acs = activation_scores(r.activations[held], tpl).mean(axis=0)
                    for route, sc in (("templates", ts), ("activations", acs)):
                        conf[route].setdefault(w, []).append((truth_name, labels[int(np.argmax(sc))]))
                confusions[(src, pname, noise)] = conf
                row = [src, pname, f"{noise:g}"]
                for route in ("templates", "activations"):
                    for w in INTENSITIES:
                        pairs = conf[route][w]
                        row.append(f"{sum(a == b for a, b in pairs)}/{len(pairs)}")
                    nn = conf[route][0.0]
                    row.append(f"{sum(a == b for a, b in nn)}/{len(nn)}")
                rec_rows.append(row)
    print(f"\n## Activations (linear fit; MAE over {len(chans)} channels, mean and worst take)\n")
    print(_table(["data", "points", "noise mm", "MAE", "worst", "precision", "recall", "residual mm"], fit_rows))
    print("\n## Recognition (correct / samples; 7 presets per weight, 4 neutral samples)\n")
    head = ["data", "points", "noise mm"] + [f"tpl {w:g}" for w in INTENSITIES] + ["tpl neutral"] + \
        [f"act {w:g}" for w in INTENSITIES] + ["act neutral"]
    print(_table(head, rec_rows))
    key = (sources[0], "68", 0.1)
    if key in per_channel:
        print(f"\n## Per-channel MAE, {key[0]}, 68 points, 0.1 mm\n")
        print(_table(["channel", "MAE"], [[c, f"{e:.3f}"] for c, e in zip(chans, per_channel[key])]))
    key = (sources[0], "68", 0.5)
    if key in confusions:
        for route in ("templates", "activations"):
            for ws, what in (((0.5, 0.7, 1.0), ">= 0.5"), ((0.3,), "0.3")):
                pairs = [p for w in ws for p in confusions[key][route][w]] + confusions[key][route][0.0]
                idx = {n: i for i, n in enumerate(labels)}
                m = np.zeros((len(labels), len(labels)), int)
                for a, b in pairs:
                    m[idx[a], idx[b]] += 1
                print(f"\n## Confusion, {route}, {key[0]}, 68 points, 0.5 mm, weights {what} (rows truth)\n")
                print(_table(["truth \\ said"] + labels, [[labels[i]] + [str(x) for x in m[i]] for i in range(len(labels))]))
    print("\n## Re-linearisation (res-1 data, 68 points, 0.1 mm)\n")
    if "res1" in sources:
        data, near = _source("res1", model0)
        verts = sets["68"]
        nv = near(verts)
        rng = np.random.default_rng(7)
        rows = []
        poses = [data.pose(data.values_for(t)) for t in truths]
        tracks = [_track(data.rest[nv], p[nv], 0.01, rng) for p in poses]
        for label, opts, st in (("linear", lin, None), ("re-linearised", FitOptions(), settler)):
            err, res, relin = [], [], 0
            t0 = time.process_time()
            for truth, tr in zip(truths, tracks):
                r = _fit(basis, st, opts, tr, verts)
                a = r.activations[HOLD + HOLD // 2]
                err.append(np.abs(a - np.array([truth.get(c, 0.0) for c in chans])).mean())
                res.append(r.reports[HOLD + HOLD // 2].residual_mm)
                relin += int(r.reports[HOLD + HOLD // 2].relinearised)
            rows.append([label, f"{np.mean(err):.3f}", f"{np.median(res):.2f}", f"{relin}/{len(truths)}",
                         f"{time.process_time() - t0:.1f}"])
        print(_table(["fit", "MAE", "residual mm", "frames re-linearised", "CPU s"], rows))


def timing(basis, settler, sets, model0) -> None:  # type: ignore[no-untyped-def]
    import sim.face
    from sim.fit.basis import preset_values
    from sim.fit.solve import FitOptions

    data, near = _source("res1", model0)
    m1 = data.model
    simulator = sim.Simulator(m1, 1 / 60.0, wrinkles=False)
    control = sim.FaceControl(m1)
    state = data.rest_state.copy()
    verts = sets["68"]
    nv = near(verts)
    from sim.facs import EXPRESSIONS

    presets = list(EXPRESSIONS)
    frames = np.empty((3600, len(nv), 3))
    t0 = time.process_time()
    for k in range(3600):
        t = k / 60.0
        seg, phase = divmod(t, 4.0)  # a preset every 4 s, fading in and out
        env = max(0.0, np.sin(np.pi * phase / 4.0)) * 0.9
        control.values[...] = data.defaults
        for ch, v in preset_values(presets[int(seg) % len(presets)], env).items():
            control.set(ch, v)
        simulator.step(state, control)
        frames[k] = state.positions[nv]
    print(f"# timing take simulated in {time.process_time() - t0:.1f} s CPU", file=sys.stderr)
    frames += np.random.default_rng(60).normal(0.0, 0.01, frames.shape)
    from sim.fit.solve import Fitter, Track

    c0, w0 = time.process_time(), time.perf_counter()
    r = Fitter(basis, settler, FitOptions()).fit(Track(np.arange(3600) / 60.0, frames, verts, 0))
    cpu, wall = time.process_time() - c0, time.perf_counter() - w0
    res = np.array([f.residual_mm for f in r.reports])
    print("\n## Speed: a 60 s take at 60 fps (3 600 frames), 68 points, 0.1 mm noise\n")
    print(_table(["CPU s", "wall s", "x real time (CPU)", "settles", "frames re-linearised", "residual mm median"],
                 [[f"{cpu:.1f}", f"{wall:.1f}", f"{60.0 / cpu:.1f}", str(r.settles),
                   str(sum(f.relinearised for f in r.reports)), f"{np.median(res):.2f}"]]))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--takes", type=int, default=30)
    ap.add_argument("--sources", nargs="+", default=["res1", "implicit", "head"])
    ap.add_argument("--skip-timing", action="store_true")
    ap.add_argument("--skip-accuracy", action="store_true")
    args = ap.parse_args()
    import sim.face
    from puppet.capture.cache import basis_for

    model0 = sim.face.default_model(0)
    settler, basis, tpl = basis_for(model0)
    sets = _point_sets(model0)
    if not args.skip_accuracy:
        accuracy(args.sources, basis, settler, tpl, sets, args.takes, model0)
    if not args.skip_timing:
        timing(basis, settler, sets, model0)
    return 0


if __name__ == "__main__":
    sys.exit(main())
