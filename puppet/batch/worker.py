"""What a batch worker process keeps between tasks, and how it is set up.

A worker runs many takes of the same few faces. Loading a face and preparing its simulator (the
scanned head's implicit integrator factorises a 6,020-vertex system and finds its lid and lip
contact pairs: about a second) would otherwise be paid by every task. Here each process keeps:

- the faces it loaded, keyed by what names them exactly: a rig file by its resolved path *and* the
  SHA-256 of its bytes, a built-in face by its kind, spec text, resolution and identity weights'
  bytes. Another identity or an edited rig file is another key, so it is never served a wrong model;
- one freshly built simulator per (face model, frame step), never stepped: each replay gets a deep
  copy of it (milliseconds), so it starts from exactly the state a new simulator has.

`BatchSetup` is the Dask worker plugin the batch client registers on every worker (local or on a
farm): it undoes the Nanny's `MALLOC_TRIM_THRESHOLD_` (which makes glibc return and re-map the
simulation's ~150 KB scratch arrays on every step, about 40 % more CPU per take in system time)
and installs the caches above in `puppet.replay`; it, `NannySetup` and `quieten_scheduler` stop the
worker's, its nanny's and the scheduler's diagnostic timers and slow the memory checks
(`quieten`: together 2 to 3 % of a core per worker with nothing running, taken from the frames).
Tasks run one at a time per process (`--nthreads 1`), so the caches need no locks (only `install`,
which the plugin may run while the first task runs)."""

from __future__ import annotations

import copy
import ctypes
import ctypes.util
import hashlib
import os
import threading
from collections import OrderedDict
from pathlib import Path
from typing import Any

#: faces kept per process (a scanned head's model is ~100 MB; a batch rarely mixes more faces)
MAX_FACES = 3
#: glibc mallopt parameters and the values set: large scratch arrays stay in the heap
M_TRIM_THRESHOLD, M_MMAP_THRESHOLD = -1, -3
TRIM_BYTES, MMAP_BYTES = 64 << 20, 32 << 20

#: the integrator's prepared arrays mapped from one shared file per machine (`puppet.batch.shared`)
SHARE_PREPARED = os.environ.get("PUPPET_BATCH_SHARED", "1") != "0"

_faces: OrderedDict[tuple[Any, ...], Any] = OrderedDict()
_simulators: dict[tuple[Any, ...], tuple[Any, Any]] = {}  # key -> (model kept alive, pristine simulator)
stats = {"face_loads": 0, "face_hits": 0, "simulators_built": 0, "simulator_copies": 0}


def face_key(rig_path: str | None, resolution: int, face: Any) -> tuple[Any, ...]:
    """What exactly names the face `puppet.live.load_face(rig_path, resolution, face)` returns."""
    if rig_path:
        p = Path(rig_path)
        try:
            digest = hashlib.sha256(p.read_bytes()).hexdigest()
        except OSError:
            digest = None  # load_face reports it; never cached (below)
        return ("rig", str(p.resolve()), digest)
    from puppet.faces import FaceChoice, parse_face

    choice = face if isinstance(face, FaceChoice) else parse_face(face, resolution)
    return ("face", choice.kind, choice.spec, choice.resolution, choice.weights.astype("<f8").tobytes())


def load_face(rig_path: str | None = None, resolution: int = 0, face: Any = None,
              bound_forehead: bool = True) -> Any:
    """`puppet.live.load_face`, remembered per process under `face_key`."""
    from puppet import live

    key = face_key(rig_path, resolution, face) + (() if bound_forehead else ("thin forehead",))
    extra = {} if bound_forehead else {"bound_forehead": False}  # (a take recorded before the layer)
    if key[0] == "rig" and key[2] is None:
        return live.load_face(rig_path, resolution, face, **extra)
    hit = _faces.get(key)
    if hit is not None:
        _faces.move_to_end(key)
        stats["face_hits"] += 1
        return hit
    loaded = live.load_face(rig_path, resolution, face, **extra)
    stats["face_loads"] += 1
    _faces[key] = loaded
    while len(_faces) > MAX_FACES:
        _, old = _faces.popitem(last=False)
        for k in [k for k, (m, _) in _simulators.items() if m is old.model]:
            del _simulators[k]
    return loaded


def new_simulator(model: Any, frame_dt: float) -> Any:
    """A simulator for `model` as `sim.Simulator(model, frame_dt)` builds it: a copy of one built
    once per process (the model itself shared, read-only)."""
    import sim

    key = (id(model), getattr(model, "hash", None), float(frame_dt))
    entry = _simulators.get(key)
    if entry is None or entry[0] is not model:
        entry = (model, sim.Simulator(model, frame_dt))
        _simulators[key] = entry
        stats["simulators_built"] += 1
    stats["simulator_copies"] += 1
    return copy.deepcopy(entry[1], _kept(model, entry[1]))


def _kept(model: Any, simulator: Any) -> dict[int, Any]:
    """What a simulator's copy shares with the original (deepcopy's memo): the model, the implicit
    integrator's prepared arrays (read-only; mapped once per machine, `puppet.batch.shared`), the
    jaw's responses and the bending's products for the jaw's turn."""
    memo: dict[int, Any] = {id(model): model}
    stepper = getattr(simulator, "_implicit", None)
    prep = getattr(stepper, "prepared", None)
    if isinstance(prep, dict):
        memo[id(prep)] = prep
        memo.update((id(a), a) for a in prep.values())
    for name in ("jaw_resp", "jaw_slope"):  # the jaw's responses, made once per face (read-only)
        a = getattr(stepper, name, None)
        if a is not None:
            memo[id(a)] = a
    for a in getattr(stepper, "_turn_b", ()):  # the margin bending's products for the jaw's turn (read-only)
        memo[id(a)] = a
    return memo


def tune_malloc() -> bool:
    """Fixed, generous glibc trim and mmap thresholds (True when set; False off glibc)."""
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        mallopt = libc.mallopt
    except (OSError, AttributeError):
        return False
    return bool(mallopt(M_MMAP_THRESHOLD, MMAP_BYTES)) and bool(mallopt(M_TRIM_THRESHOLD, TRIM_BYTES))


_installed = [False]
_install_lock = threading.Lock()


def install() -> None:
    """This process replays through the caches above (idempotent: once per process). Locked: the
    batch's plugin may set a worker up on its event loop while the worker's first task, already
    running, does so too."""
    from puppet import replay

    with _install_lock:
        if not _installed[0]:
            tune_malloc()
            if SHARE_PREPARED:
                from puppet.batch import shared

                shared.install()
            _installed[0] = True
        replay.use_loaders(load_face=load_face, new_simulator=new_simulator)


#: a Dask server's diagnostics that wake its event loop while a task computes: the 20 ms "event
#: loop blocked" tick (about 1 % of a core per process) and the worker's statistical profiler (a
#: stack sample of the task thread every 10 ms, for the dashboard's profile page)
QUIET = ("tick", "profile", "profile-cycle")
#: how often the worker and its nanny check the worker's memory (Dask's default 100 ms: ~1 % of a
#: core per process with nothing running); limits still hold, checked each second
MEMORY_CHECK_MS = 1000.0


def quieten(server: Any) -> None:
    """Stop a Dask server's (worker, nanny, scheduler) diagnostic periodic callbacks for good and
    slow its memory check."""
    pcs = getattr(server, "periodic_callbacks", {})
    for name in QUIET:  # taken out of the list, not only stopped: a server still starting (a worker or
        # nanny joining the farm after the batch's plugins were registered, or a worker its nanny
        # restarted) sets its plugins up first and then starts every periodic callback it lists
        pc = pcs.pop(name, None)
        if pc is not None:
            pc.stop()
    pc = pcs.get("memory_monitor")
    if pc is not None and pc.callback_time < MEMORY_CHECK_MS:
        pc.stop()
        pc.callback_time = MEMORY_CHECK_MS
        pc.start()


def clear() -> None:
    _faces.clear()
    _simulators.clear()


def quieten_scheduler(dask_scheduler: Any) -> None:
    """`quieten` on the scheduler (`Client.run_on_scheduler` passes it by this argument's name)."""
    quieten(dask_scheduler)


def _plugin_classes() -> tuple[Any, Any]:
    from dask.distributed import NannyPlugin, WorkerPlugin

    class BatchSetup(WorkerPlugin):
        """Registered by the batch client on every worker: `install()` and `quieten()` there."""

        idempotent = True
        name = "puppet-batch-setup"

        def setup(self, worker: Any) -> None:
            install()
            quieten(worker)

    class NannySetup(NannyPlugin):
        """`quieten()` in every worker's nanny (without restarting its worker)."""

        idempotent = True
        restart = False
        name = "puppet-batch-nanny"

        def setup(self, nanny: Any) -> None:
            quieten(nanny)

    return BatchSetup, NannySetup


def plugin() -> Any:
    """A new BatchSetup worker plugin (dask imported only when a batch runs)."""
    return _plugin_classes()[0]()


def nanny_plugin() -> Any:
    """A new NannySetup nanny plugin."""
    return _plugin_classes()[1]()


def counters() -> dict[str, int]:
    """This process's cache counters (a farm's client reads them with `Client.run`)."""
    return dict(stats)
