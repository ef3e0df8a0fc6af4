"""The batch client: connects to a Dask scheduler (or starts a local cluster of one worker process
per core on 127.0.0.1), submits one task per output (a long video: its chunks and their join),
writes each result into the output folder as it lands, and reports failures with their reasons
while the rest finish. A worker that dies mid-task has its task run again elsewhere by the
scheduler (Dask's `allowed-failures`); the jobs have no side effects, so running twice is harmless."""

from __future__ import annotations

import hashlib
import json
import logging
import os
import sys
import threading
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from puppet.batch import jobs, worker
from puppet.batch.plan import EXPORT_KINDS, Output, chunks, drop_token, load, output_key, output_names, \
    reach_token, select, up_to_date, write_outputs
from puppet.errors import PuppetError

SUFFIXES = {"export": (".jsonl",), "recognize": (".jsonl", ".csv", ".c3d", ".pc2"),
            "fit": (".csv", ".c3d", ".pc2", ".wav")}
CONNECT_TIMEOUT = 20.0


@dataclass
class Report:
    written: list[Path] = field(default_factory=list)
    skipped: list[str] = field(default_factory=list)
    failed: dict[str, str] = field(default_factory=dict)  # input path -> first reason
    workers: int = 0
    tasks: int = 0
    spans: dict[str, list[tuple[float, float, str, float]]] = field(default_factory=dict)  # take hash -> spans
    library_takes: int = 0  # library takes whose expression spans this batch stored
    warnings: list[str] = field(default_factory=list)  # what the single commands would have warned


def plan(action: str, selection: list[str], kinds: list[str], opts: dict[str, Any], library: str | None) -> list[Output]:
    items = [load(p) for p in select(selection, library, SUFFIXES[action])]
    outs: list[Output] = []
    if action == "export":
        for kind in kinds:
            names = output_names(items, EXPORT_KINDS[kind])
            o = dict(opts) if kind == "mp4" else {"fps": opts.get("fps")}
            outs += [Output(i, action, n, output_key(i, action, n, o), o) for i, n in zip(items, names)]
    else:
        suffix = ".jsonl" if action == "fit" else ".expressions.json"
        for i, n in zip(items, output_names(items, suffix)):
            outs.append(Output(i, action, n, output_key(i, action, n, opts), opts))
    return outs


def connect(scheduler: str | None, workers: int | None) -> tuple[Any, Any]:
    """(client, local cluster or None). Python's cyclic garbage collector is held off while Dask is
    imported and the client connects: importing its ~650 modules makes objects that live as long
    as the process, and the collector's passes over them cost ~12 % of the import's CPU."""
    import gc

    collecting = gc.isenabled()
    if collecting:
        gc.disable()
    try:
        return _connect(scheduler, workers)
    finally:
        if collecting:
            gc.enable()


def _connect(scheduler: str | None, workers: int | None) -> tuple[Any, Any]:
    import warnings

    from dask.distributed import Client, LocalCluster

    # a task carries its input's bytes (no shared folder needed): a 38 MB point cache made Dask warn
    # 'Sending large graph of size 37.99 MiB ...' in six lines on the user's terminal, about its own API
    warnings.filterwarnings("ignore", message="Sending large graph", category=UserWarning)

    if scheduler:
        _check_tls(scheduler)
        _reach(scheduler)
        try:
            client = Client(scheduler, timeout=CONNECT_TIMEOUT)
        except (OSError, TimeoutError) as err:
            raise PuppetError(f"cannot reach the Dask scheduler at {scheduler} ({err}); start `dask "
                              "scheduler` there or check the address it printed") from err
        except Exception as err:  # noqa: BLE001 - whatever Dask makes of another program's bytes
            # an SSH or web server on that port: Dask took its first bytes for a frame length and
            # tried to allocate exabytes (MemoryError), or could not unpack them (struct.error, ...)
            other = " (or a tcp:// one: name it so)" if scheduler.startswith("tls://") else ""
            raise PuppetError(f"what answers at {scheduler} is not a Dask scheduler{other}: Dask could not read "
                              "its reply; check the address `dask scheduler` printed") from err
        return client, None
    import dask

    n = workers or max(1, os.cpu_count() or 1)
    with dask.config.set({"distributed.worker.profile.enabled": False}):  # no stack sampling in the tasks' way
        cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, host="127.0.0.1",
                               dashboard_address="127.0.0.1:0", silence_logs=logging.CRITICAL)
    return Client(cluster), cluster


def _reach(scheduler: str) -> None:
    """One plain TCP connection to the scheduler's port before Dask's: Dask retries a refused
    connection until its timeout (a scheduler may still be starting), so a closed port or an unknown
    host kept the user waiting CONNECT_TIMEOUT (20 s) before a word was said."""
    import socket
    from urllib.parse import urlsplit

    url = urlsplit(scheduler)
    what = f"cannot reach the Dask scheduler at {scheduler}"
    todo = "start `dask scheduler` there or check the address it printed"
    try:
        with socket.create_connection((url.hostname, url.port), timeout=CONNECT_TIMEOUT):
            pass
    except ConnectionRefusedError as err:
        raise PuppetError(f"{what} (nothing listens on port {url.port}); {todo}") from err
    except socket.gaierror as err:
        raise PuppetError(f"{what} (unknown host {url.hostname}); {todo}") from err
    except TimeoutError as err:
        raise PuppetError(f"{what} (no answer within {CONNECT_TIMEOUT:g} s); {todo}") from err
    except OSError as err:
        raise PuppetError(f"{what} ({err.strerror or err}); {todo}") from err


def _check_tls(scheduler: str) -> None:
    """A tls:// scheduler needs Dask's TLS settings for a client; without them Dask's connect
    raised a TypeError traceback ('TLS expects a `ssl_context` argument')."""
    if not scheduler.startswith("tls://"):
        return
    from distributed.security import Security

    try:
        context = Security().get_connection_args("client").get("ssl_context")
    except (OSError, ValueError) as err:  # a certificate file missing or not PEM
        raise PuppetError(f"--scheduler {scheduler}: Dask's TLS settings cannot be used ({err})") from err
    if context is None:
        raise PuppetError(f"--scheduler {scheduler}: Dask has no TLS settings for a client; set "
                          "distributed.comm.tls.ca-file, .client.cert and .client.key (in ~/.config/dask/ or as "
                          "DASK_DISTRIBUTED__COMM__TLS__CA_FILE, ...__CLIENT__CERT, ...__CLIENT__KEY)")


def check_farm(client: Any) -> int:
    """Every worker must run this very program (version and sources); returns the worker count.
    One round trip when the farm has workers (waiting for one only when it has none yet)."""
    from dask.distributed import TimeoutError as DaskTimeout

    mine = jobs.identity()
    theirs = client.run(jobs.identity)
    if not theirs:
        try:
            client.wait_for_workers(1, timeout=CONNECT_TIMEOUT)
        except (DaskTimeout, TimeoutError, OSError) as err:
            raise PuppetError(f"no Dask worker joined the scheduler within {CONNECT_TIMEOUT:g} s") from err
        theirs = client.run(jobs.identity)
    for addr, ident in theirs.items():
        if tuple(ident) != mine:
            raise PuppetError(f"worker {addr} runs puppet {ident[0]} (sources {ident[1]}), this machine "
                              f"{mine[0]} (sources {mine[1]}): install the same version on every machine")
    return len(theirs)


#: Seconds between two looks at the farm's workers while a batch runs.
WATCH_INTERVAL = 2.0


def watch_workers(client: Any, scheduler: str, interval: float = WATCH_INTERVAL) -> tuple[threading.Thread, threading.Event]:
    """A thread saying (one line each time) when the farm is left without a worker while the batch
    waits, and when one joins again: the scheduler keeps the tasks for a worker to come, and the
    batch waited without a word, forever. Set the event to stop it."""
    done = threading.Event()

    def look() -> None:
        alone = False
        while True:
            # looked at more often while alone, and once more when the batch ends alone: a worker that
            # joins and finishes the last tasks between two looks is still reported
            finished = done.wait(min(interval, 0.5) if alone else interval)
            if finished and not alone:
                return
            try:
                n = len(client.scheduler_info().get("workers", {}))
            except Exception:  # closing, or the scheduler gone (the batch says that itself)
                if finished:
                    return
                continue
            if n == 0 and not alone and not finished:
                print(f"puppet: batch: the farm has no worker now; its tasks wait for one: start `dask worker "
                      f"{scheduler}` to go on, or Ctrl+C (the files written are kept)", file=sys.stderr, flush=True)
            elif n > 0 and alone:
                print(f"puppet: batch: {n} worker{'' if n == 1 else 's'} in the farm again; going on",
                      file=sys.stderr, flush=True)
            alone = n == 0
            if finished:
                return

    t = threading.Thread(target=look, name="batch-workers", daemon=True)
    t.start()
    return t, done


def _video_plan(o: Output, chunk_frames: int) -> list[int] | None:
    """The frames' ticks when the video is long enough to split, else None (one task)."""
    if chunk_frames <= 0 or o.opts.get("view", "shaded") == "trails":  # trails: one renderer sees all
        return None
    try:
        from puppet.session import read_session

        s = read_session(o.item.path)
        rate, ticks = s.tick_rate, s.ticks
    except Exception:  # the worker reports what is wrong with it
        return None
    fps = o.opts.get("fps") or 30.0
    n = max(1, int(round(ticks / rate * fps)))
    if n <= chunk_frames:
        return None
    return [min(ticks, int(round(j / fps * rate))) for j in range(n)]


def quieten_farm(client: Any) -> threading.Thread:
    """Register the batch's plugins (`puppet.batch.worker`: per-process caches, malloc thresholds,
    the diagnostic timers stopped) on the workers, their nannies and the scheduler, on a thread:
    three round trips through the scheduler that the tasks need not wait for (a task installs the
    caches itself, `jobs._staged`), so they are made once the tasks are submitted. Join it before
    closing the client."""

    def register() -> None:
        steps = (lambda: client.register_plugin(worker.plugin()),
                 lambda: client.register_plugin(worker.nanny_plugin()),
                 lambda: client.run_on_scheduler(worker.quieten_scheduler))
        for step in steps:
            try:
                step()
            except Exception:  # no nanny (`dask worker --no-nanny`), a scheduler refusing `run`, closing
                pass

    t = threading.Thread(target=register, name="batch-plugins", daemon=True)
    t.start()
    return t


def run(action: str, selection: list[str], out_dir: Path, *, kinds: list[str] | None = None,
        opts: dict[str, Any] | None = None, scheduler: str | None = None, workers: int | None = None,
        chunk_frames: int = 0, library: str | None = None, force: bool = False, bar: bool = True) -> Report:
    opts = opts or {}
    rep = Report()
    if not out_dir.is_dir():
        if out_dir.exists():
            raise PuppetError(f"--out {out_dir}: a file, not a folder; name a folder for the outputs")
        if not out_dir.parent.is_dir():
            raise PuppetError(f"{out_dir}: neither it nor its parent folder exists")
        try:
            out_dir.mkdir(exist_ok=True)
        except OSError as err:
            raise PuppetError(f"--out {out_dir}: cannot create the folder ({err.strerror})") from err
    outs = plan(action, selection, kinds or [], opts, library)
    todo = []
    for o in outs:
        if o.item.error:
            rep.failed.setdefault(str(o.item.path), o.item.error)
        elif not force and up_to_date(out_dir, o):
            rep.skipped.append(o.name)
            if o.action == "recognize" and o.item.path.suffix.lower() == ".jsonl":
                try:
                    _keep_spans(rep, o, (out_dir / o.name).read_bytes())
                except OSError:
                    pass
        else:
            todo.append(o)
    if not todo:
        _store_spans_or_warn(rep, library)
        return rep
    client, cluster = connect(scheduler, workers)
    plugins: list[threading.Thread] = []
    stop_watching: Any = lambda: None  # noqa: E731
    try:
        rep.workers = check_farm(client)
        if scheduler:  # a farm's workers may all go; a local cluster's nannies bring theirs back
            watcher, watched = watch_workers(client, scheduler)
            plugins.append(watcher)
            stop_watching = watched.set
        dest = reach_token(out_dir)
        try:
            _submit_and_collect(client, todo, out_dir, chunk_frames, rep, bar, dest,
                                submitted=lambda: plugins.append(quieten_farm(client)))
            try:  # workers that joined (or left) while it ran
                rep.workers = max(1, len(client.scheduler_info()["workers"]))
            except Exception:
                pass
        finally:
            drop_token(out_dir, dest)
            _remove_parts(out_dir, todo)
    finally:
        stop_watching()
        for t in plugins:
            t.join(CONNECT_TIMEOUT)
        client.close()
        if cluster is not None:
            cluster.close()
    _store_spans_or_warn(rep, library)
    return rep


def _store_spans_or_warn(rep: Report, library: str | None) -> None:
    try:
        store_spans(rep, library)
    except Exception as err:  # the outputs are written; the library is an index of them
        print(f"puppet: warning: the expressions were written but not stored in the take library: {err}",
              file=sys.stderr)


def _submit_and_collect(client: Any, todo: list[Output], out_dir: Path, chunk_frames: int, rep: Report,
                        show: bool, dest: dict[str, str] | None = None, submitted: Any = None) -> None:
    """Every task submitted (then `submitted()` called, and the progress bar's module imported:
    what the workers need not wait for), each result written as it lands."""
    from dask.distributed import as_completed

    final: dict[Any, list[Output]] = {}
    helpers: dict[Any, Output] = {}
    fn = {"fit": jobs.fit_capture, "recognize": jobs.recognize_input}
    together: dict[str, list[Output]] = {}  # an input's exports: one task, one simulation
    for o in todo:
        tag = f"{o.name}-{o.key[:12]}"
        files, origin = o.item.files, str(o.item.path)
        size = _size(o)
        ticks = _video_plan(o, chunk_frames) if o.action == "export" and o.name.endswith(".mp4") else None
        if ticks is None:
            if o.action == "export":
                together.setdefault(origin, []).append(o)
            else:
                final[client.submit(fn[o.action], files, origin, o.name, o.opts, key=f"{o.action}-{tag}",
                                    priority=size)] = [o]
            continue
        parts = chunks(len(ticks), chunk_frames)
        o.chunks = parts
        ckpt = client.submit(jobs.mp4_checkpoints, files, origin, ticks, [a for a, _ in parts],
                             key=f"mp4-checkpoints-{tag}", priority=size)
        pieces = [client.submit(jobs.mp4_chunk, files, origin, o.opts, ticks, a, b, ckpt, k,
                                key=f"mp4-chunk-{k}-{tag}", priority=size) for k, (a, b) in enumerate(parts)]
        for f in (ckpt, *pieces):
            helpers[f] = o
        fut = client.submit(jobs.mp4_join, o.name, origin, o.opts, *pieces, key=f"mp4-join-{tag}", priority=size)
        final[fut] = [o]
    for origin, group in together.items():
        key = "export-" + hashlib.sha256("".join(o.key for o in group).encode()).hexdigest()[:24]
        final[client.submit(jobs.export_outputs, group[0].item.files, origin,
                            [(o.name, o.opts) for o in group], dest, key=key, priority=_size(group[0]))] = group
    rep.tasks = len(final) + len(helpers)
    if submitted is not None:
        submitted()
    from tqdm import tqdm

    desc = f"batch on {rep.workers} worker{'' if rep.workers == 1 else 's'}"
    with tqdm(total=rep.tasks, desc=desc, unit="task", file=sys.stderr, dynamic_ncols=True,
              disable=None if show else True) as progress:  # None: a bar on a terminal only, not in a log
        for fut in as_completed(list(final) + list(helpers)):
            progress.update(1)
            group = final.get(fut)
            if group is None:
                continue  # a chunk: its join collects it
            origin = str(group[0].item.path)
            try:
                result = fut.result()
            except Exception as err:  # the job's reason (or the worker's death, past the retries)
                if _scheduler_lost(err):  # no take's fault: every task still out is cancelled with it
                    logging.getLogger("distributed.client").setLevel(logging.CRITICAL)  # its close's tracebacks
                    raise PuppetError(f"lost the connection to the Dask scheduler mid-batch ({len(rep.written)} "
                                      "files written, kept); start it again and run the same command: it "
                                      "does only what is missing") from None
                rep.failed.setdefault(origin, _reason(err, origin))
                continue
            finally:
                for h in [h for h, ho in helpers.items() if any(ho is o for o in group)]:
                    del helpers[h]  # frees the chunks' frames on the workers
            if fut.key.startswith("mp4-join-") or group[0].action != "export":
                result = {group[0].name: result}
            rep.warnings += [w for w in result.get(jobs.WARNINGS, ()) if w not in rep.warnings]
            for o in group:
                try:
                    rep.written += write_outputs(out_dir, o, result[o.name])
                except Exception as err:
                    rep.failed.setdefault(origin, f"{out_dir}: cannot write {o.name}: {err}")
                if o.action == "recognize" and o.item.path.suffix.lower() == ".jsonl":
                    _keep_spans(rep, o, result[o.name][o.name])


def _size(o: Output) -> int:
    """A task's priority: its input's size in bytes (a take's length), so the longest start first
    and the short ones fill the end (a shorter tail when the last task runs alone)."""
    return len(o.item.files.get(o.item.path.name, b""))


def _keep_spans(rep: Report, o: Output, text: bytes) -> None:
    """The spans `puppet recognize --json` printed, as the library keeps them, by the take's hash."""
    try:
        spans = [(float(s["start"]), float(s["end"]), str(s["expression"]),
                  float(s["scores"].get(s["expression"], 0.0))) for s in json.loads(text)]
    except (ValueError, KeyError, TypeError, AttributeError):
        return
    rep.spans[hashlib.sha256(o.item.files[o.item.path.name]).hexdigest()] = spans


def store_spans(rep: Report, library: str | None) -> None:
    """Recognized expressions of takes the library knows (by content hash) go into it, as `puppet
    takes check` would put them; no library (or none yet) is no error: the files are written."""
    if not rep.spans:  # an export: nothing to store, and the library's modules not imported
        return
    from puppet.library import library_path
    from puppet.library.store import Library

    path = library_path(library)
    if path is None or not path.exists():
        return
    with Library(path) as lib:
        for digest, spans in rep.spans.items():
            rep.library_takes += lib.set_spans(digest, spans)


def _remove_parts(out_dir: Path, todo: list[Output]) -> None:
    """Half-written files a worker killed mid-write left beside the outputs (safefile's hidden
    `.STEM.*.part*` names); the task ran again elsewhere and wrote the whole file. One listing of
    the folder (a glob per output compiled a pattern each: ~20 ms after the last result). A file
    another run is writing now (a second batch into the same folder, a `puppet replay --out`
    there) is left to it: removing it failed that run's export."""
    from safefile import part_in_use

    prefixes = tuple(f".{Path(o.name).stem}." for o in todo)
    try:
        names = os.listdir(out_dir)
    except OSError:
        return
    for name in names:
        if name.startswith(prefixes) and any(name.startswith(p) and ".part" in name[len(p):] for p in prefixes):
            if part_in_use(out_dir / name):
                continue
            try:
                (out_dir / name).unlink()
            except OSError:
                pass


def _scheduler_lost(err: BaseException) -> bool:
    """Whether a task's future was cancelled because the client lost the scheduler."""
    return type(err).__name__ == "FutureCancelledError" and "connection" in str(err).lower()


def _reason(err: BaseException, origin: str) -> str:
    name = type(err).__name__
    text = str(err).strip() or name
    if name == "KilledWorker":
        return f"{origin}: the workers running it died repeatedly ({text[:200]})"
    if isinstance(err, jobs.JobFailed) or name in ("JobFailed",):
        return text if origin in text else f"{origin}: {text}"
    return f"{origin}: {name}: {text[:300]}"
