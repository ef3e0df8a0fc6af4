"""Batch exports on Dask: N takes of S seconds (default 16 x 10 s) exported to PC2 and to a 720p
MP4, one after the other with `puppet replay TAKE --out FILE` (a process per take, as a user would
script it) and with `puppet batch export` on the local cluster (one worker process per core); then
PC2 through an external `dask scheduler` with 1 and with 2 `dask worker` processes; then the
scheduling cost of a task (a no-op task's round trip on that farm). Every batch output is compared
with the single export's bytes. Figures are wall-clock (best of --repeats, the two sides
alternating), plus the CPU seconds the local runs used (their processes' user + system time),
measured in this one run.

On a machine shared with other users' sessions, Linux's autogroup scheduling gives each session
(terminal) one fair share of the CPUs under contention: a local cluster's workers, in this
session, then share the time one process would get, and only the start-up saved shows. Farm
workers started in their own sessions (as on separate machines) each get a share. Read the CPU
seconds for the work saved and the farm's 1 vs 2 workers for the parallel speed-up.

Each farm run also prints where its CPU went (workers' user and system time and how often they
were preempted, nannies, scheduler, client), what other users' processes took and what the host
stole; `--ceiling` adds the machine's own 1 vs 2 process ratio for the same task without Dask and
for a compute kernel (`benchmarks/ceiling.py`), and the farm's ratio as a share of it.

Run:  nice .venv/bin/python benchmarks/batch.py [--face procedural] [--takes 16] [--seconds 10] [--skip-mp4]
      [--farm-only] [--ceiling] [--json]
"""

from __future__ import annotations

import argparse
import filecmp
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
PUPPET = [sys.executable, "-m", "puppet"]


def write_takes(folder: Path, n: int, seconds: float) -> list[Path]:
    """n takes of `seconds` at 60 Hz: three muscles ramping and one oscillating, different per take."""
    from puppet import live
    from puppet.mapping.config import MappingSpec
    from puppet.session import SessionWriter

    face = live.load_face()
    muscles = [i for i, c in enumerate(face.vocab.channels) if c.kind == "muscle"]
    out = []
    for k in range(n):
        rng = np.random.default_rng(k)
        moving = rng.choice(muscles, 4, replace=False)
        values = np.array(face.vocab.defaults(), dtype=np.float64)
        header = live.session_header(face, MappingSpec(name="bench", bindings=[], combine={}), 60.0, ["bench://"])
        p = folder / f"take{k:02d}.jsonl"
        ticks = int(seconds * 60)
        with SessionWriter(p, header, fsync_seconds=None) as w:
            for t in range(ticks):
                x = t / ticks
                values[moving[:3]] = [min(1.0, 0.8 * x), min(1.0, 0.5 * x * x), 0.6 * (1 - x)]
                values[moving[3]] = 0.5 + 0.4 * np.sin(2 * np.pi * t / 90)
                w.values(t, values)
                w.tick(t + 1)
            w.close(ticks)
        out.append(p)
    return out


CPU = [0.0]  # CPU seconds of the last timed() call's processes (children, reaped)


def _children_cpu() -> float:
    import resource

    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def timed(cmd: list[str], **kw) -> float:  # type: ignore[no-untyped-def]
    c = _children_cpu()
    t = time.perf_counter()
    r = subprocess.run(cmd, capture_output=True, text=True, **kw)
    if r.returncode != 0:
        raise SystemExit(f"failed: {' '.join(cmd)}\n{r.stderr[-2000:]}")
    CPU[0] = _children_cpu() - c
    return time.perf_counter() - t


def serial(takes: list[Path], out: Path, suffix: str) -> tuple[float, float]:
    out.mkdir(exist_ok=True)
    wall = cpu = 0.0
    for t in takes:
        wall += timed(PUPPET + ["replay", str(t), "--out", str(out / (t.stem + suffix))])
        cpu += CPU[0]
    return wall, cpu


def same(a: Path, b: Path, suffix: str, takes: list[Path]) -> int:
    return sum(filecmp.cmp(a / (t.stem + suffix), b / (t.stem + suffix), shallow=False) for t in takes)


class Farm:
    """`dask scheduler` and `dask worker`s on 127.0.0.1, stopped by PID."""

    def __init__(self, folder: Path) -> None:
        self.folder, self.procs = folder, []
        self.file = folder / "scheduler.json"
        self._spawn("scheduler", "--host", "127.0.0.1", "--port", "0", "--dashboard-address", "127.0.0.1:0",
                    "--scheduler-file", str(self.file))
        while not self.file.exists() or not self.file.read_text().strip():
            time.sleep(0.1)
        time.sleep(0.2)
        self.address = json.loads(self.file.read_text())["address"]

    def _spawn(self, *args: str) -> None:
        log = open(self.folder / f"{args[0]}{len(self.procs)}.log", "wb")
        self.procs.append(subprocess.Popen([sys.executable, "-m", "dask", *args], stdout=log,
                                           stderr=subprocess.STDOUT, start_new_session=True))

    def drop_worker(self, total: int) -> None:
        """Stop the newest worker (by its process group) and wait until `total` remain."""
        p = self.procs.pop()
        os.killpg(p.pid, signal.SIGTERM)
        p.wait(30)
        from dask.distributed import Client

        with Client(self.address, timeout=30) as c:
            for _ in range(600):
                if len(c.scheduler_info()["workers"]) <= total:
                    return
                time.sleep(0.1)

    def add_worker(self, total: int) -> None:
        self._spawn("worker", "--scheduler-file", str(self.file), "--host", "127.0.0.1", "--dashboard-address",
                    "127.0.0.1:0", "--nworkers", "1", "--nthreads", "1")
        from dask.distributed import Client

        with Client(self.address, timeout=30) as c:
            c.wait_for_workers(total, timeout=120)

    def stop(self) -> None:
        for p in reversed(self.procs):
            try:
                os.killpg(p.pid, signal.SIGTERM)
            except ProcessLookupError:
                pass
        for p in reversed(self.procs):
            try:
                p.wait(20)
            except subprocess.TimeoutExpired:
                os.killpg(p.pid, signal.SIGKILL)
                p.wait()


def warm(address: str, take: Path) -> None:
    """Every worker loads the face and compiles the simulation once (what its first task would pay)."""
    from dask.distributed import Client

    from puppet.batch import jobs

    with Client(address, timeout=30) as c:
        c.run(jobs.export_take, {take.name: take.read_bytes()}, str(take), take.stem + ".pc2", {"fps": None})


def machine_cpu() -> tuple[float, float]:
    """(busy, idle) CPU seconds of the whole machine since boot, all cores (/proc/stat; idle
    includes I/O wait)."""
    v = [int(x) for x in open("/proc/stat").readline().split()[1:9]]
    tick = os.sysconf("SC_CLK_TCK")
    return (sum(v) - v[3] - v[4]) / tick, (v[3] + v[4]) / tick


def steal() -> float:
    """CPU seconds the hypervisor gave to other machines while this one's CPUs wanted to run, since
    boot (/proc/stat's steal column)."""
    return int(open("/proc/stat").readline().split()[8]) / os.sysconf("SC_CLK_TCK")


def farm_roles(farm: Farm) -> dict[str, float]:
    """CPU seconds used so far by the farm's processes by role (scheduler, nannies, workers; a
    worker's time split into user and system), and the workers' involuntary context switches (how
    often a worker was made to wait for a CPU)."""
    import psutil

    out = {"scheduler": 0.0, "nanny": 0.0, "worker_user": 0.0, "worker_system": 0.0, "worker_preempted": 0.0}
    for i, p in enumerate(farm.procs):
        try:
            top = psutil.Process(p.pid)
            for q in [top, *top.children(recursive=True)]:
                t = q.cpu_times()
                if i == 0:
                    out["scheduler"] += t.user + t.system
                elif q.pid == top.pid and top.children():
                    out["nanny"] += t.user + t.system
                else:  # a worker (under its nanny, or `--no-nanny` alone)
                    out["worker_user"] += t.user
                    out["worker_system"] += t.system
                    out["worker_preempted"] += q.num_ctx_switches().involuntary
        except psutil.Error:
            pass
    return out


def farm_cpu(farm: Farm) -> float:
    """CPU seconds used so far by the farm's processes (scheduler, nannies, workers)."""
    r = farm_roles(farm)
    return r["scheduler"] + r["nanny"] + r["worker_user"] + r["worker_system"]


def farm_run(farm: Farm, cmd: list[str], client: Any) -> dict[str, Any]:
    """One timed batch on the farm: wall, the CPU it used (client, farm), what other users' processes
    used meanwhile, and per-task figures from the scheduler's task stream (compute time of each task
    on its worker, and how long the first worker to run out of tasks waited for the last)."""
    b0, i0 = machine_cpu()
    r0 = farm_roles(farm)
    s0 = steal()
    t0 = time.time()
    wall = timed(cmd)
    b1, i1 = machine_cpu()
    r1 = farm_roles(farm)
    roles = {k: r1[k] - r0[k] for k in r0}
    ours = CPU[0] + sum(v for k, v in roles.items() if k != "worker_preempted")
    stream = [t for t in client.get_task_stream(start=t0) if str(t["key"]).startswith("export-")]
    comp: dict[str, list[tuple[float, float]]] = {}
    for t in stream:
        for ss in t["startstops"]:
            if ss["action"] == "compute":
                comp.setdefault(t["worker"], []).append((ss["start"] - t0, ss["stop"] - t0))
    spans = [x for v in comp.values() for x in v]
    ends = [max(b for _, b in v) for v in comp.values()]
    seen = client.run_on_scheduler(_scheduler_times, t0, client.id)
    return {"wall": wall, "cpu_ours": ours, "cpu_others": max(0.0, b1 - b0 - ours), "idle": i1 - i0,
            "tasks": len(spans), "task_s": sum(b - a for a, b in spans) / max(1, len(spans)),
            "first_start": min((a for a, _ in spans), default=0.0), "tail": max(ends) - min(ends) if ends else 0.0,
            "after_last": wall - max(ends) if ends else 0.0,
            "per_worker": sorted(len(v) for v in comp.values()), "client_cpu": CPU[0], **roles,
            "steal": steal() - s0, **timeline(wall, comp, {k: v - t0 for k, v in seen.items()}),
            "workers_tasks": [[round(b - a, 2) for a, b in sorted(v)] for _, v in sorted(comp.items())]}


#: the parts of a farm run's wall, in order (`timeline`)
PARTS = ("launch", "setup", "dispatch", "compute", "gaps", "tail", "exit")


def _scheduler_times(since: float, watcher: str, dask_scheduler: Any = None) -> dict[str, float]:
    """When the scheduler saw the batch's client connect, its first export task arrive and the
    client leave (time.time(), this machine's clock)."""
    out = {}
    for t, msg in dask_scheduler.get_events("all"):
        if t >= since and isinstance(msg, dict) and msg.get("client") != watcher:
            if msg.get("action") == "add-client":
                out.setdefault("connected", t)
            elif msg.get("action") == "remove-client":
                out["left"] = t
    arrived = [tr.timestamp for tr in dask_scheduler.transition_log
               if tr.timestamp >= since and str(tr.key).startswith("export-")]
    if arrived:
        out["submitted"] = min(arrived)
    return out


def timeline(wall: float, comp: dict[str, list[tuple[float, float]]], seen: dict[str, float]) -> dict[str, float]:
    """A batch's wall split into what happened one after the other (seconds): the client's start
    until the scheduler saw it connect (Python, imports, reading and hashing the takes), until its
    first task arrived (checking the workers' program, registering the plugins), until a worker
    started it, the workers' time (mean over workers: computing, the gaps between two tasks, and
    idle at the end while another worker ran its last task), and from the last task's end to the
    command's exit. The parts add up to the wall."""
    if not comp:
        return {}
    first = min(a for v in comp.values() for a, _ in v)
    last = max(b for v in comp.values() for _, b in v)
    connected = seen.get("connected", first)
    submitted = min(max(seen.get("submitted", first), connected), first)
    busy = gaps = idle = 0.0
    for v in comp.values():
        v = sorted(v)
        busy += sum(b - a for a, b in v)
        gaps += (v[0][0] - first) + sum(v[k + 1][0] - v[k][1] for k in range(len(v) - 1))
        idle += last - v[-1][1]
    n = len(comp)
    return {"t_launch": min(connected, first), "t_setup": submitted - min(connected, first),
            "t_dispatch": first - submitted, "t_compute": busy / n, "t_gaps": gaps / n, "t_tail": idle / n,
            "t_exit": wall - last}


def _noop(x: int) -> int:
    return x


def overhead(address: str, n: int = 400) -> float:
    """Seconds per task of no-op tasks submitted at once and gathered (scheduling and transport)."""
    from dask.distributed import Client, wait

    with Client(address, timeout=30) as c:
        wait(c.map(_noop, range(20), pure=False))  # connections warm
        t = time.perf_counter()
        fs = c.map(_noop, range(n), pure=False)
        wait(fs)
        return (time.perf_counter() - t) / n


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--takes", type=int, default=16)
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--repeats", type=int, default=2, help="PC2 and farm runs per side (best counts)")
    ap.add_argument("--skip-mp4", action="store_true")
    ap.add_argument("--farm-only", action="store_true", help="only the external scheduler's figures")
    ap.add_argument("--mp4-only", action="store_true", help="only MP4: serial against the local cluster")
    ap.add_argument("--face", default=None, help="the takes' face (--face spec; default: the default face, the scan)")
    ap.add_argument("--ceiling", action="store_true", help="also run the same task without Dask and a compute "
                    "kernel as 1 vs 2 processes (benchmarks/ceiling.py) and print the farm's ratio against them")
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args()
    if a.face:
        os.environ["PUPPET_FACE"] = a.face  # the takes record it; every export and worker replays it
    res: dict[str, Any] = {"face": os.environ.get("PUPPET_FACE", "ict"), "takes": a.takes, "seconds": a.seconds, "cores": os.cpu_count() or 1,
                                         "load_before": os.getloadavg()[0]}
    with tempfile.TemporaryDirectory(prefix="puppet-bench-batch-") as tmp:
        d = Path(tmp)
        (d / "takes").mkdir()
        takes = write_takes(d / "takes", a.takes, a.seconds)
        (d / "local").mkdir()
        if a.farm_only:
            serial(takes, d / "single", ".pc2")
        # PC2: serial single exports vs the local cluster, alternating
        local = PUPPET + ["batch", "export", str(d / "takes"), "--out", str(d / "local"), "--to", "pc2", "--force"]
        runs_s, runs_l, cpu_s, cpu_l = [], [], [], []
        for _ in range(0 if a.farm_only or a.mp4_only else a.repeats):
            w, c = serial(takes, d / "single", ".pc2")
            runs_s.append(w)
            cpu_s.append(c)
            runs_l.append(timed(local))
            cpu_l.append(CPU[0])
        if not a.farm_only and not a.mp4_only:
            res["pc2_serial_s"], res["pc2_local_cluster_s"] = min(runs_s), min(runs_l)
            res["pc2_serial_cpu_s"], res["pc2_local_cluster_cpu_s"] = min(cpu_s), min(cpu_l)
            res["pc2_local_speedup"] = res["pc2_serial_s"] / res["pc2_local_cluster_s"]
            res["pc2_runs"] = [[round(x, 1), round(y, 1)] for x, y in zip(runs_s, runs_l)]
            res["pc2_runs_cpu"] = [[round(x, 1), round(y, 1)] for x, y in zip(cpu_s, cpu_l)]
            res["pc2_identical"] = same(d / "single", d / "local", ".pc2", takes)
            # a re-run with nothing changed
            res["pc2_rerun_s"] = timed(local[:-1])
        if not a.skip_mp4 and not a.farm_only:
            one = write_takes(d, 1, 1 / 60)[0]  # a one-tick take: its export is nearly all start-up
            res["mp4_startup_one_export_s"] = timed(PUPPET + ["replay", str(one), "--out", str(d / "one.mp4")])
            res["mp4_serial_s"], res["mp4_serial_cpu_s"] = serial(takes, d / "single", ".mp4")
            res["mp4_local_cluster_s"] = timed(PUPPET + ["batch", "export", str(d / "takes"), "--out",
                                                         str(d / "local"), "--to", "mp4"])
            res["mp4_local_cluster_cpu_s"] = CPU[0]
            res["mp4_local_speedup"] = res["mp4_serial_s"] / res["mp4_local_cluster_s"]
            res["mp4_identical"] = same(d / "single", d / "local", ".mp4", takes)
        if not a.mp4_only:
            # an external scheduler: 1 worker, then 2, alternating
            farm = Farm(d)
            try:
                (d / "farm").mkdir()
                cmd = PUPPET + ["batch", "export", str(d / "takes"), "--out", str(d / "farm"), "--to", "pc2",
                                "--force", "--scheduler", farm.address]
                tiny = write_takes(d, 1, 0.1)[0]
                farm.add_worker(1)
                warm(farm.address, tiny)  # each new worker loads the face once, as a farm's workers do
                from dask.distributed import Client

                watch = Client(farm.address, timeout=30)  # reads the scheduler's task stream
                watch.get_task_stream(start=time.time())  # the scheduler starts recording it
                runs: dict[int, list[dict[str, Any]]] = {1: [], 2: []}
                loads = []
                for r in range(a.repeats):
                    for n in (1, 2):
                        if n == 2:
                            farm.add_worker(2)
                            warm(farm.address, tiny)
                        loads.append(round(os.getloadavg()[0], 1))
                        runs[n].append(farm_run(farm, cmd, watch))
                    if r + 1 < a.repeats:
                        farm.drop_worker(1)
                watch.close()
                one_w, two_w = [x["wall"] for x in runs[1]], [x["wall"] for x in runs[2]]
                res["pc2_farm_1_worker_s"], res["pc2_farm_2_workers_s"] = min(one_w), min(two_w)
                res["pc2_farm_speedup"] = res["pc2_farm_1_worker_s"] / res["pc2_farm_2_workers_s"]
                res["pc2_farm_runs"] = [[round(x, 1), round(y, 1)] for x, y in zip(one_w, two_w)]
                res["pc2_farm_pair_ratios"] = [round(x / y, 2) for x, y in zip(one_w, two_w)]
                res["pc2_farm_loads"] = loads
                res["pc2_farm_detail"] = {n: [{k: (round(v, 3) if isinstance(v, float) else v) for k, v in x.items()}
                                              for x in rs] for n, rs in runs.items()}
                res["pc2_farm_identical"] = same(d / "single", d / "farm", ".pc2", takes)
                res["task_overhead_ms"] = overhead(farm.address) * 1e3
            finally:
                farm.stop()
            if a.ceiling:
                sys.path.insert(0, str(ROOT / "benchmarks"))
                import ceiling  # type: ignore[import-not-found]

                res["ceiling"] = ceiling.measure(["l2", "export"], a.repeats, str(takes[0]), str(d / "farm"))
        res["load_after"] = os.getloadavg()[0]
    if a.json:
        print(json.dumps(res))
        return 0
    n = a.takes
    print(f"face {res['face']}: {n} takes of {a.seconds:g} s, {res['cores']} cores, load {res['load_before']:.1f} before, "
          f"{res['load_after']:.1f} after")
    if "pc2_serial_s" in res:
        print(f"PC2  serial `puppet replay --out`: {res['pc2_serial_s']:.1f} s ({res['pc2_serial_cpu_s']:.1f} s CPU); "
              f"local cluster: {res['pc2_local_cluster_s']:.1f} s ({res['pc2_local_cluster_cpu_s']:.1f} s CPU) -> "
              f"{res['pc2_local_speedup']:.2f}x wall, {res['pc2_serial_cpu_s'] / res['pc2_local_cluster_cpu_s']:.2f}x "
              f"CPU ({res['pc2_identical']}/{n} byte-identical); re-run, nothing changed: {res['pc2_rerun_s']:.1f} s")
        print(f"     each run, serial vs cluster: wall {res['pc2_runs']}, CPU {res['pc2_runs_cpu']}")
    if not a.skip_mp4 and not a.farm_only:
        print(f"MP4  serial: {res['mp4_serial_s']:.1f} s ({res['mp4_serial_cpu_s']:.1f} s CPU); local cluster: "
              f"{res['mp4_local_cluster_s']:.1f} s ({res['mp4_local_cluster_cpu_s']:.1f} s CPU) -> "
              f"{res['mp4_local_speedup']:.2f}x ({res['mp4_identical']}/{n} byte-identical); one export's start-up "
              f"{res['mp4_startup_one_export_s']:.1f} s, paid {n} times serially")
    if a.mp4_only:
        return 0
    print(f"PC2  external scheduler: 1 worker {res['pc2_farm_1_worker_s']:.1f} s, 2 workers "
          f"{res['pc2_farm_2_workers_s']:.1f} s -> {res['pc2_farm_speedup']:.2f}x ({res['pc2_farm_identical']}/{n} "
          f"byte-identical); each run, 1 vs 2 workers: {res['pc2_farm_runs']} (load at each start {res['pc2_farm_loads']})")
    print(f"     1 vs 2 workers per pair: {res['pc2_farm_pair_ratios']}")
    for n, rs in res["pc2_farm_detail"].items():
        for x in rs:
            print(f"     {n} worker{'s' if n > 1 else ''}: {x['wall']:.1f} s; {x['tasks']} tasks {x['per_worker']}, "
                  f"{x['task_s']:.2f} s each on its worker, first starts at {x['first_start']:.1f} s, "
                  f"tail {x['tail']:.1f} s, exit {x['after_last']:.2f} s after the last; CPU: ours {x['cpu_ours']:.1f} s, other users' {x['cpu_others']:.1f} s, "
                  f"idle {x['idle']:.1f} s, stolen by the host {x['steal']:.1f} s")
            print(f"       each worker's tasks in order (s): {x['workers_tasks']}")
            print(f"       where ours went: workers {x['worker_user']:.1f} s user + {x['worker_system']:.1f} s system "
                  f"(preempted {x['worker_preempted']:.0f} times), nannies {x['nanny']:.2f} s, scheduler "
                  f"{x['scheduler']:.2f} s, client {x['client_cpu']:.2f} s")
    print("     where 2 workers lose against half of 1 worker's run (s; each pair; the parts add up to the "
          "difference):")
    for one, two in zip(res["pc2_farm_detail"][1], res["pc2_farm_detail"][2]):
        if "t_compute" not in one or "t_compute" not in two:
            continue
        parts = {name: two[f"t_{name}"] - one[f"t_{name}"] / 2 for name in PARTS}
        cpu = [(x["worker_user"] + x["worker_system"]) / max(1, x["tasks"]) for x in (one, two)]
        print(f"       {two['wall'] - one['wall'] / 2:+.2f} = " + ", ".join(f"{k} {v:+.2f}" for k, v in parts.items())
              + f" (1 worker: " + ", ".join(f"{k} {one[f't_{k}']:.2f}" for k in PARTS) + f"; workers' CPU a task "
              f"{cpu[0]:.2f} s on one, {cpu[1]:.2f} s on each of two)")
    print(f"scheduling: {res['task_overhead_ms']:.2f} ms per no-op task")
    for c in res.get("ceiling", []):
        print(f"ceiling: {c['kernel']} as 1 vs 2 processes {c['ratio']:.2f}x (pairs {c['pairs']}; CPU each of two "
              f"{c['cpu_two'] / c['cpu_one']:.2f}x one's); the farm's {res['pc2_farm_speedup']:.2f}x is "
              f"{res['pc2_farm_speedup'] / c['ratio']:.0%} of it")
    return 0


if __name__ == "__main__":
    sys.exit(main())
