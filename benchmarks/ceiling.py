"""How well this machine runs two processes at once: reference kernels run by one process, then by
two at the same time (each in its own session, as two farm workers are), and the ratio of the work
done per second, 2 x (one alone) / (the slower of the two together). A perfect two-core machine
gives 2.00; a virtual machine whose two CPUs share a physical core, its caches or its memory bus
gives less, and no batch can beat that ceiling. Kernels, lightest to heaviest in memory traffic:

- `l1`: a compiled, vectorised loop of multiply-adds over 16 KB (fits in L1): the cores' own
  arithmetic (two virtual CPUs on one physical core's two threads would share it);
- `l2`: the same over 768 KB (fits in a core's L2);
- `stream`: copying 64 MB arrays (memory bandwidth, shared by the cores);
- `sim`: the scanned head's simulation of a 10 s take, 600 ticks, no posing and no output;
- `pose`: the same plus posing all 26,719 scan vertices a frame as float32 (what a PC2 holds);
- `sim-private`, `export-private`: the same, each process with its own copy of the integrator's
  prepared arrays (what the batch's workers did before `puppet.batch.shared`);
- `export`: the batch's whole task (`puppet.batch.jobs.export_outputs`) writing the PC2 + OBJ to
  the disk (`--out-dir`, default a temporary folder beside the benchmark) or to tmpfs
  (`/dev/shm`), without Dask.

Each side runs --repeats times, alternating (1, 2, 1, 2, ...); the best of each counts and every
pair is printed. Figures are wall-clock per process; CPU seconds (the process's own) show whether a
process was slowed by sharing (same CPU, longer wall: waiting for a core) or by the other core
(more CPU for the same work: caches, memory, frequency).

Run:  nice .venv/bin/python benchmarks/ceiling.py [--kernels l1 l2 stream sim pose export] [--repeats 3] [--json]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any, Callable

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
KERNELS = ("l1", "l2", "stream", "sim", "sim-private", "pose", "export", "export-private", "export-tmpfs")


def _fma_kernel() -> Callable[[np.ndarray, int], float]:
    import numba

    @numba.njit(cache=True, fastmath=True)
    def run(a: np.ndarray, reps: int) -> float:  # pragma: no cover - compiled
        for _ in range(reps):  # independent lanes: vectorised, limited by the core's arithmetic and loads
            for i in range(a.size):
                a[i] = a[i] * 0.999 + 0.001
        return a[0]

    return run


def _setup(kernel: str, take: str, out_dir: str) -> Callable[[], None]:
    """The kernel's work, set up and warmed (compiled, caches loaded) in this process."""
    if kernel in ("l1", "l2"):
        run = _fma_kernel()
        a = np.random.default_rng(0).random((16 << 10 if kernel == "l1" else 768 << 10) // 8)
        reps = (1 << 33) // a.size  # the same number of multiply-adds either way
        run(a, 1)
        return lambda: run(a, reps)
    if kernel == "stream":
        src, dst = np.ones(8 << 20), np.empty(8 << 20)  # 64 MB each

        def copy() -> None:
            for _ in range(60):
                np.copyto(dst, src)

        copy()
        return copy
    from puppet.batch import jobs, worker
    from puppet.replay import Replayer, build_performance
    from puppet.session import read_session

    worker.install()
    if kernel.startswith("export"):
        files = {Path(take).name: Path(take).read_bytes()}
        folder = Path(tempfile.mkdtemp(prefix="ceiling-", dir="/dev/shm" if kernel == "export-tmpfs" else out_dir))
        import atexit
        import shutil

        atexit.register(shutil.rmtree, folder, True)
        from puppet.batch.plan import reach_token

        dest = reach_token(folder)

        def export() -> None:
            jobs.export_outputs(files, take, [(Path(take).stem + ".pc2", {"fps": None})], dest)

        export()
        return export
    perf = build_performance(read_session(Path(take)), None)
    from puppet.export.scan import posed, scan_dressing

    dressing = scan_dressing(perf.face.model)
    frame = np.empty((len(dressing.rest), 3), dtype="<f4") if dressing is not None else None

    def simulate() -> None:
        rp = Replayer(perf)
        for k in range(1, perf.ticks + 1):
            rp.seek(k)
            if kernel == "pose" and dressing is not None:
                frame[...] = posed(dressing, rp.state)

    simulate()
    return simulate


def child(kernel: str, take: str, out_dir: str) -> None:
    """Set up, say `ready`, wait for `go` on stdin, run once, print {wall, cpu} as JSON."""
    if kernel.endswith("-private"):  # each process its own copy of the prepared arrays
        os.environ["PUPPET_BATCH_SHARED"] = "0"
        kernel = kernel[:-len("-private")]
    work = _setup(kernel, take, out_dir)
    print("ready", flush=True)
    sys.stdin.readline()
    c, t = time.process_time(), time.perf_counter()
    work()
    print(json.dumps({"wall": time.perf_counter() - t, "cpu": time.process_time() - c}), flush=True)


def _start(kernel: str, take: str, out_dir: str) -> subprocess.Popen[str]:
    p = subprocess.Popen([sys.executable, __file__, "--child", kernel, take, out_dir], stdin=subprocess.PIPE,
                         stdout=subprocess.PIPE, text=True, start_new_session=True)
    assert p.stdout is not None
    if p.stdout.readline().strip() != "ready":
        raise SystemExit(f"{kernel}: the kernel's process failed to start")
    return p


def together(kernel: str, n: int, take: str, out_dir: str) -> list[dict[str, float]]:
    """n processes set up, then started at once; each one's {wall, cpu}."""
    procs = [_start(kernel, take, out_dir) for _ in range(n)]
    for p in procs:
        assert p.stdin is not None
        p.stdin.write("go\n")
        p.stdin.flush()
    out = []
    for p in procs:
        assert p.stdout is not None
        out.append(json.loads(p.stdout.readline()))
        p.wait()
    return out


def measure(kernels: list[str], repeats: int, take: str, out_dir: str) -> list[dict[str, Any]]:
    """1 vs 2 processes for each kernel, the kernels taking turns in every repeat (so an A/B pair
    sees the same load); per kernel the ratio of work per second (2.0 = two whole cores)."""
    ones: dict[str, list[dict[str, float]]] = {k: [] for k in kernels}
    twos: dict[str, list[list[dict[str, float]]]] = {k: [] for k in kernels}
    for _ in range(repeats):
        for k in kernels:
            ones[k].append(together(k, 1, take, out_dir)[0])
            twos[k].append(together(k, 2, take, out_dir))
    res = []
    for k in kernels:
        one = min(x["wall"] for x in ones[k])
        two = min(max(x["wall"] for x in pair) for pair in twos[k])
        res.append({"kernel": k, "one_s": one, "two_s": two, "ratio": 2 * one / two,
                    "pairs": [round(2 * a["wall"] / max(x["wall"] for x in b), 2) for a, b in zip(ones[k], twos[k])],
                    "cpu_one": min(x["cpu"] for x in ones[k]),
                    "cpu_two": min(max(x["cpu"] for x in p) for p in twos[k]),
                    "cpu_pairs": [round(max(x["cpu"] for x in b) / a["cpu"], 2) for a, b in zip(ones[k], twos[k])]})
    return res


def reference_take(folder: Path) -> Path:
    """One 10 s take of the default face, as `benchmarks/batch.py` writes them."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    from batch import write_takes  # type: ignore[import-not-found]

    return write_takes(folder, 1, 10.0)[0]


def main() -> int:
    if len(sys.argv) > 1 and sys.argv[1] == "--child":
        child(*sys.argv[2:5])
        return 0
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--kernels", nargs="+", default=list(KERNELS), choices=KERNELS)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--out-dir", default=str(ROOT / "benchmarks"), help="where the disk export writes")
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args()
    load = os.getloadavg()[0]
    with tempfile.TemporaryDirectory(prefix="puppet-bench-ceiling-") as tmp:
        take = str(reference_take(Path(tmp)))
        with tempfile.TemporaryDirectory(prefix="ceiling-out-", dir=a.out_dir) as out:
            res = measure(a.kernels, a.repeats, take, out)
    if a.json:
        print(json.dumps({"load_before": load, "load_after": os.getloadavg()[0], "kernels": res}))
        return 0
    print(f"1 vs 2 processes, {os.cpu_count()} CPUs, load {load:.1f} before, {os.getloadavg()[0]:.1f} after")
    for r in res:
        print(f"  {r['kernel']:>12}: one {r['one_s']:.2f} s, two {r['two_s']:.2f} s -> {r['ratio']:.2f}x "
              f"(pairs {r['pairs']}); CPU one {r['cpu_one']:.2f} s, each of two {r['cpu_two']:.2f} s "
              f"({r['cpu_two'] / r['cpu_one']:.2f}x; pairs {r['cpu_pairs']})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
