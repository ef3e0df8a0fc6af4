"""How fast the face simulates: for resolutions 0, 1, 2 and both integrators, microseconds per step,
substeps per 60 Hz frame, and the share of a 60 Hz frame on one core.

    .venv/bin/python benchmarks/sim_step.py [--resolutions 0 1 2] [--frames 30] [--no-scan]

Method: the default face (gravity on) under the happiness preset, wrinkles off (their layer's cost is
printed on its own line), numba kernels warmed up first; times are the CPU time of this thread
(time.thread_time: one core's work, not inflated when other processes share the machine), best of 3
runs of --frames frames. A
"step" is one RK2 substep (two force evaluations) or one implicit substep (one spring pass and one
prefactored solve). The scanned head (sim.face.scan, the default face of the application) is
timed the same way after the procedural resolutions, with its build time (rig transfer, compile), the
posing of all its 26,719 vertices (`ScanDressing.pose`, the renderer's side of a frame) and its cost
as a ratio to resolution 0's in the same run, and at the live loop's faster ticks (120 and 240 Hz:
one substep a tick, so 2 and 4 solves per 60 Hz frame), a tick as the live loop runs it at 60 and
120 Hz (`puppet live` headless picks the rate from the face's measured step, `puppet.tick_rate`:
the step with the input, the wrinkle surface once a 60 Hz frame and the next step's input-free solve made between ticks), and the prefactored solve alone,
by supernodes (`sim.supernodal`, what the step runs) against the plain column-by-column sweeps over
the same factors (what it ran before; the same bits), in alternating batches, and the substep's solve
from the symmetric factor (L and D, what new takes use) against the one from L and U, with the factors
in the caches and with 12 MB written before each solve, in alternating batches. The last block
compares the two integrators' transients on the default face: time for the left mouth corner to
reach 90 % of its settled AU12 displacement.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

FRAME = 1.0 / 60.0


def _frame_ms(sim: object, model: object, control: object, frames: int) -> float:
    state = model.rest_state()  # type: ignore[attr-defined]
    for _ in range(2):
        sim.step(state, control)  # type: ignore[attr-defined]
    best = float("inf")
    for _ in range(3):
        t0 = time.thread_time()
        for _ in range(frames):
            sim.step(state, control)  # type: ignore[attr-defined]
        best = min(best, (time.thread_time() - t0) / frames)
    return best * 1e3


def _column_form(arrays: dict) -> tuple:  # type: ignore[type-arg]
    """The supernodal factors (sim.supernodal) back in plain column form: L's strictly lower and U's
    strictly upper entries by columns (int64 pointers, int32 rows, values) and U's diagonal."""
    sn, rp, ri, vp, lv, uv, tp, tv = (arrays[k] for k in ("sn_ptr", "r_ptr", "r_idx", "v_ptr", "lv", "uv", "t_ptr",
                                                           "tv"))
    n = int(sn[-1])
    lcols: list[list[tuple[int, float]]] = [[] for _ in range(n)]
    ucols: list[list[tuple[int, float]]] = [[] for _ in range(n)]
    for k in range(len(sn) - 1):
        s, w = int(sn[k]), int(sn[k + 1] - sn[k])
        rows = ri[rp[k]:rp[k + 1]]
        m = len(rows)
        tri = tv[tp[k]:tp[k + 1]].reshape(w, w).T  # [row, column] in the run
        low = lv[vp[k]:vp[k + 1]].reshape(w, m)  # [column in run, row below]
        up = uv[vp[k]:vp[k + 1]].reshape(m, w)  # [column below, row in run]
        for jj in range(w):
            lcols[s + jj] += [(s + ii, tri[ii, jj]) for ii in range(jj + 1, w)]
            lcols[s + jj] += [(int(r), low[jj, i]) for i, r in enumerate(rows)]
            ucols[s + jj] += [(s + ii, tri[ii, jj]) for ii in range(jj)]
        for i, c in enumerate(rows):
            ucols[int(c)] += [(s + ii, up[i, ii]) for ii in range(w)]
    out = []
    for cols in (lcols, ucols):
        ptr = np.concatenate([[0], np.cumsum([len(c) for c in cols])]).astype(np.int64)
        out += [ptr, np.array([r for c in cols for r, _ in sorted(c)], dtype=np.int32),
                np.array([v for c in cols for _, v in sorted(c)], dtype=np.float64)]
    return (*out, arrays["u_diag"])


def _column_sweeps_kernel():  # type: ignore[no-untyped-def]
    import numba

    @numba.njit(nogil=True)
    def sweeps(y, l_ptr, l_idx, l_val, u_ptr, u_idx, u_val, u_diag):  # type: ignore[no-untyped-def]
        for j in range(y.shape[0]):
            for p in range(l_ptr[j], l_ptr[j + 1]):
                r = l_idx[p]
                for d in range(3):
                    y[r, d] -= l_val[p] * y[j, d]
        for j in range(y.shape[0] - 1, -1, -1):
            for d in range(3):
                y[j, d] = y[j, d] / u_diag[j]
            for p in range(u_ptr[j], u_ptr[j + 1]):
                r = u_idx[p]
                for d in range(3):
                    y[r, d] -= u_val[p] * y[j, d]

    return sweeps


def _solve_vs_columns(solver: object, batches: int = 15) -> str:
    """The prefactored solve by supernodes against the plain column sweeps, alternating batches of
    20 solves; checks that both give the same bits."""
    from sim.supernodal import _sn_sweeps

    plain = _column_form(solver.arrays)  # type: ignore[attr-defined]
    sweeps = _column_sweeps_kernel()
    b = np.random.default_rng(2).normal(size=(solver.n, 3))  # type: ignore[attr-defined]
    y1, y2 = b.copy(), b.copy()
    sweeps(y1, *plain)
    _sn_sweeps(y2, *solver.factors, solver.work)  # type: ignore[attr-defined]
    same = y1.tobytes() == y2.tobytes()
    best = {"supernodes": float("inf"), "columns": float("inf")}
    for _ in range(batches):
        for key in best:
            t0 = time.thread_time()
            for _ in range(20):
                if key == "columns":
                    sweeps(y1, *plain)
                else:
                    _sn_sweeps(y2, *solver.factors, solver.work)  # type: ignore[attr-defined]
            best[key] = min(best[key], (time.thread_time() - t0) / 20 * 1e3)
    return (f"    the solve alone: by supernodes {best['supernodes']:.2f} ms, by columns {best['columns']:.2f} ms "
            f"({best['columns'] / best['supernodes']:.2f}x; same bits: {same})")


def _symmetric_vs_lu(solver: object, batches: int = 15) -> str:
    """The substep's solve from the symmetric factor (`_sym_sweeps`: L and D) against the one from
    L and U (`_sn_sweeps`), alternating batches of 20 solves, once with the factors in the caches
    and once with 12 MB written before each solve (as the rest of a live tick and other programs
    evict them); and how far apart their answers are."""
    from sim.supernodal import _sn_sweeps, _sym_sweeps

    b = np.random.default_rng(3).normal(size=(solver.n, 3))  # type: ignore[attr-defined]
    y1, y2 = b.copy(), b.copy()
    _sn_sweeps(y1, *solver.factors, solver.work)  # type: ignore[attr-defined]
    _sym_sweeps(y2, *solver.sym_factors, solver.work)  # type: ignore[attr-defined]
    apart = float(np.abs(y1 - y2).max() / np.abs(y1).max())
    evict = np.zeros(12 * 2**20 // 8)
    out = []
    for cold in (False, True):
        best = {"LU": [], "LDL^T": []}
        for _ in range(batches):
            for key in best:
                spent = 0.0
                for _ in range(20):
                    y = b.copy()
                    if cold:
                        evict += 1.0
                    t0 = time.thread_time()
                    if key == "LU":
                        _sn_sweeps(y, *solver.factors, solver.work)  # type: ignore[attr-defined]
                    else:
                        _sym_sweeps(y, *solver.sym_factors, solver.work)  # type: ignore[attr-defined]
                    spent += time.thread_time() - t0
                best[key].append(spent / 20 * 1e3)
        lu, sym = np.median(best["LU"]), np.median(best["LDL^T"])
        out.append(f"{'after 12 MB written' if cold else 'factors in the caches'}: L and U {lu:.3f} ms, "
                   f"L and D {sym:.3f} ms ({lu / sym:.2f}x)")
    read = lambda *ks: sum(solver.arrays[k].nbytes for k in ks) / 2**20  # type: ignore[attr-defined]  # noqa: E731
    return (f"    the substep's solve, medians of {batches} batches: " + "; ".join(out) +
            f"; values read {read('lv', 'uv', 'tv', 'u_diag'):.2f} -> {read('lv', 'tv', 'u_diag'):.2f} MB; "
            f"answers apart by {apart:.1e} of the largest")


def _live_ticks(model: object, control: object, rate: float, frames: int) -> str:
    """A tick as the live loop runs it (puppet.live.LiveCore): the step with the input (the muscles'
    activations moving every tick), the wrinkle surface (once a 60 Hz frame: the headless loop makes
    it for the ticks it draws, `LiveCore.surface_later`), then the next step's input-free solve
    between ticks (`Simulator.prepare`); CPU time of this thread, mean over 8 x `frames` ticks (the
    surface's mean over all of them, so the parts add up to a tick's average)."""
    from sim.integrator import Simulator

    sim = Simulator(model, 1.0 / rate, wrinkles=True)  # type: ignore[arg-type]
    state, c = model.rest_state(), control.copy()  # type: ignore[attr-defined]
    base = np.array(c.values)
    muscle = sim._is_muscle
    parts: dict[str, list[float]] = {"step": [], "surface": [], "between ticks": []}
    per_frame = max(1, int(round(rate / 60.0)))
    for k in range(8 * frames + 10):
        c.values[muscle] = base[muscle] * (0.8 + 0.2 * np.sin(k / 10.0))
        t0 = time.thread_time()
        sim.step(state, c, surface=False)  # type: ignore[arg-type]
        t1 = time.thread_time()
        if (k + 1) % per_frame == 0:
            sim.surface(state)
        t2 = time.thread_time()
        sim.prepare(state)
        t3 = time.thread_time()
        if k >= 10:
            for key, dt in zip(parts, (t1 - t0, t2 - t1, t3 - t2)):
                parts[key].append(dt)
    tick = sum(float(np.mean(v)) for v in parts.values()) * 1e3
    share = 100 * tick * rate / 60.0 / (1e3 * FRAME)
    return (f"    live loop at {rate:.0f} Hz (input each tick, wrinkles, the next solve between ticks): {tick:.2f} ms a tick "
            f"({share:.1f}% of a 60 Hz frame; " + ", ".join(f"{k} {1e3 * np.mean(v):.2f}" for k, v in parts.items())
            + f" ms; the surface once every {per_frame} ticks)")


def _rise_time(model: object, method: str) -> float:
    from sim.integrator import Simulator
    from sim.state import FaceControl

    c = FaceControl()
    c.set("zygomaticus_major_l", 1.0)
    sim = Simulator(model, wrinkles=False, method=method)  # type: ignore[arg-type]
    state = model.rest_state()  # type: ignore[attr-defined]
    i = model.mesh.landmarks["mouth_corner_l"]  # type: ignore[attr-defined]
    track = []
    for _ in range(120):
        sim.step(state, c)
        track.append(np.linalg.norm(state.positions[i] - model.rest[i]))  # type: ignore[attr-defined]
    final = track[-1]
    k = next(n for n, d in enumerate(track) if d >= 0.9 * final)
    return (k + 1) * FRAME


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--resolutions", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--frames", type=int, default=30)
    parser.add_argument("--no-scan", action="store_true", help="leave out the scanned head")
    args = parser.parse_args()

    from sim import facs
    from sim.build import compile_model
    from sim.integrator import Simulator
    from sim.face import default_rig
    from sim.state import FaceControl

    control = FaceControl()
    facs.apply_expression(control, "happiness")
    print(f"{'res':>3} {'verts':>6} {'springs':>7} {'method':>8} {'auto':>4} {'substeps':>8} "
          f"{'us/step':>8} {'ms/frame':>8} {'% of 60Hz':>9}")
    models = {}
    for res in args.resolutions:
        t0 = time.perf_counter()
        model = compile_model(default_rig(res))
        models[res] = model
        compile_s = time.perf_counter() - t0
        auto = Simulator(model, wrinkles=False).method
        for method in ("rk2", "implicit"):
            sim = Simulator(model, wrinkles=False, method=method)
            frames = args.frames if sim.substeps * len(model.spring_indices) < 3e6 else 3
            ms = _frame_ms(sim, model, control, frames)
            mark = "*" if method == auto else ""
            print(f"{res:>3} {model.n_vertices:>6} {len(model.spring_indices):>7} {method:>8} {mark:>4} "
                  f"{sim.substeps:>8} {1e3 * ms / sim.substeps:>8.1f} {ms:>8.2f} {100 * ms / (1e3 * FRAME):>8.1f}%")
        print(f"    compile_model: {compile_s:.2f} s")
    auto_ms = {}
    for res, model in models.items():
        sim = Simulator(model, wrinkles=False)
        auto_ms[res] = _frame_ms(sim, model, control, args.frames)
    if not args.no_scan:
        _scan(control, args.frames, auto_ms)
    if 0 in models:
        from sim.wrinkles.layer import apply_wrinkles

        m = models[0]
        state = m.rest_state()
        state.age = 70.0
        apply_wrinkles(m, state)
        t0 = time.thread_time()
        for _ in range(30):
            apply_wrinkles(m, state)
        print(f"wrinkle layer (res 0, age 70): {(time.thread_time() - t0) / 30 * 1e3:.2f} ms/frame")
        for method in ("rk2", "implicit"):
            print(f"AU12 rise to 90 % (res 0, {method}): {_rise_time(m, method) * 1e3:.0f} ms")


def _scan(control: object, frames: int, auto_ms: dict[int, float]) -> None:
    """The scanned head: build, simulate (auto method), pose the whole scan; ratios to the
    procedural faces timed in this run."""
    from sim.build import compile_model
    from sim.face.scan.dressing import build_dressing
    from sim.face.scan.rig import SCAN_PARAMS, scan_rig
    from sim.integrator import Simulator

    t0 = time.perf_counter()
    rig = scan_rig()
    t1 = time.perf_counter()
    model = compile_model(rig, SCAN_PARAMS)
    t2 = time.perf_counter()
    sim = Simulator(model, wrinkles=False)
    ms = _frame_ms(sim, model, control, frames)
    print(f"scan {model.n_vertices:>6} {len(model.spring_indices):>7} {sim.method:>8} {'*':>4} {sim.substeps:>8} "
          f"{1e3 * ms / sim.substeps:>8.1f} {ms:>8.2f} {100 * ms / (1e3 * FRAME):>8.1f}%")
    print(f"    scan_rig (the shipped rig): {t1 - t0:.2f} s, compile_model: {t2 - t1:.2f} s")
    for res, base in auto_ms.items():
        print(f"    scan / resolution {res} (each with its auto method): {ms / base:.2f}x")
    # `puppet live` headless ticks at 240 Hz (puppet.live.LIVE_TICK_RATE; a window at 60 Hz): one
    # implicit substep a tick, four ticks per 60 Hz frame
    for rate in (120.0, 240.0):
        fast = Simulator(model, 1.0 / rate, wrinkles=False)
        ticks = int(rate / 60.0)
        tick_ms = _frame_ms(fast, model, control, frames * ticks)
        print(f"    at {rate:.0f} Hz ticks: {tick_ms:.2f} ms a tick, {ticks * tick_ms:.2f} ms per 60 Hz frame "
              f"({100 * ticks * tick_ms / (1e3 * FRAME):.1f}% of a 60 Hz frame)")
    for rate in (60.0, 120.0):
        print(_live_ticks(model, control, rate, frames))
    print(_solve_vs_columns(sim._implicit.solver))  # type: ignore[attr-defined]
    print(_symmetric_vs_lu(sim._implicit.solver))  # type: ignore[attr-defined]
    t0 = time.thread_time()
    Simulator(model, 1.0 / 50.0, wrinkles=False)  # a substep no other simulator here used
    print(f"    a simulator's set-up (its matrix factored, nothing kept): {time.thread_time() - t0:.2f} s; "
          f"the same face and substep again: ", end="")
    t0 = time.thread_time()
    Simulator(model, 1.0 / 50.0, wrinkles=False)
    print(f"{time.thread_time() - t0:.3f} s")
    dressing = build_dressing(model)
    state = model.rest_state()
    sim.settle(state, control, max_seconds=1.0)  # type: ignore[arg-type]
    best = float("inf")
    for _ in range(3):
        t0 = time.thread_time()
        for _ in range(frames):
            dressing.pose(state.surface, control)
        best = min(best, (time.thread_time() - t0) / frames)
    print(f"    pose all 26719 vertices: {best * 1e3:.2f} ms ({100 * best / FRAME:.1f}% of a 60 Hz frame)")


if __name__ == "__main__":
    main()
