"""`puppet batch` on a real Dask farm (a `dask scheduler` and two `dask worker` processes on
127.0.0.1) and on the local cluster: outputs equal the single commands', a bad take is reported
while the rest finish, a re-run does only what changed, a worker killed mid-task has its task
run again, a long video split into chunks equals the single export."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from farm import Farm
from puppet.cli import main
from puppet.library.store import Library
from takes import write_take


@pytest.fixture(scope="module")
def farm(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Farm]:
    f = Farm(tmp_path_factory.mktemp("farm"))
    try:
        yield f
    finally:
        f.stop()


def replay_out(take: Path, out: Path, *extra: str) -> bytes:
    """What `puppet replay TAKE --out OUT` writes."""
    assert main(["replay", str(take), "--out", str(out), *extra]) == 0
    return out.read_bytes()


def test_a_bad_scheduler_address_is_one_line(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """Checked before anything runs: Dask's parser raised a traceback on `foo`, and a batch with
    every output up to date never connected, so `tcp://HOST:notaport` passed unnoticed."""
    take = tmp_path / "a.jsonl"
    write_take(take, seed=1)
    out = tmp_path / "out"
    assert main(["batch", "export", str(take), "--out", str(out), "--to", "csv", "--workers", "1"]) == 0
    capsys.readouterr()
    for bad in ("foo", "tcp://127.0.0.1", "tcp://127.0.0.1:notaport", "http://127.0.0.1:8786"):
        assert main(["batch", "export", str(take), "--out", str(out), "--to", "csv", "--scheduler", bad]) == 2
        _, err = capsys.readouterr()
        assert err.count("\n") == 1 and "tcp://HOST:PORT" in err, (bad, err)


def test_a_closed_scheduler_port_is_said_at_once(tmp_path: Path, capsys: pytest.CaptureFixture,
                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    """Dask retries a refused connection until its connect timeout (20 s): the user waited that long
    to learn nothing listens there. Now one line naming the port, exit 2, without Dask's wait (its
    timeout is cut to 3 s here so the old code fails fast, with its 'Timed out' message)."""
    import socket

    import puppet.batch.run as batch_run

    monkeypatch.setattr(batch_run, "CONNECT_TIMEOUT", 3.0)
    with socket.socket() as s:  # a port just free on this machine: nothing listens there
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    take = tmp_path / "a.jsonl"
    write_take(take, seed=1)
    code = main(["batch", "export", str(take), "--out", str(tmp_path / "out"), "--to", "csv",
                 "--scheduler", f"tcp://127.0.0.1:{port}"])
    _, err = capsys.readouterr()
    assert code == 2 and err.count("\n") == 1, err
    assert f"nothing listens on port {port}" in err and "dask scheduler" in err, err
    assert not (tmp_path / "out" / "a.csv").exists()


def test_export_through_the_farm_equals_replay(farm: Farm, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    shoot = tmp_path / "shoot"
    takes = [write_take(shoot / f"take{k}.jsonl", ticks=30 + 15 * k, seed=k, performer="ana") for k in range(3)]
    (shoot / "broken.jsonl").write_text('{"t": "header", "format": "facepuppet-session", "version": 1}\n')
    out = tmp_path / "out"
    out.mkdir()
    code = main(["batch", "export", str(shoot), "--out", str(out), "--to", "pc2,csv", "--scheduler", farm.address])
    _, err = capsys.readouterr()
    assert code == 2
    failed = [line for line in err.splitlines() if line.startswith("puppet: failed:")]
    assert len(failed) == 1 and str(shoot / "broken.jsonl") in failed[0], err
    single = tmp_path / "single"
    single.mkdir()
    for t in takes:
        for suffix in (".pc2", ".csv"):
            want = replay_out(t, single / (t.stem + suffix))
            assert (out / (t.stem + suffix)).read_bytes() == want, t.stem + suffix
        assert (out / (t.stem + ".obj")).read_bytes() == (single / (t.stem + ".obj")).read_bytes()
    assert not (out / "broken.pc2").exists()
    capsys.readouterr()

    # a re-run does only what changed: one take re-recorded, the broken one repaired
    stamps = {p.name: p.stat().st_mtime_ns for p in out.iterdir() if p.is_file()}
    write_take(takes[1], ticks=50, seed=9)
    (shoot / "broken.jsonl").unlink()
    assert main(["batch", "export", str(shoot), "--out", str(out), "--to", "pc2,csv",
                 "--scheduler", farm.address]) == 0
    line = capsys.readouterr().out
    assert "4 outputs up to date" in line and "(1 task)" in line, line
    for p in out.iterdir():
        if p.is_file():
            assert (p.stat().st_mtime_ns != stamps[p.name]) == p.name.startswith("take1."), p.name
    assert (out / "take1.pc2").read_bytes() == replay_out(takes[1], single / "take1.pc2")
    # the batch quietened the farm's diagnostic timers (each wakes a process 50 times a second)
    def _timers(dask_worker=None, dask_scheduler=None):  # type: ignore[no-untyped-def]  # sent by value
        pcs = (dask_worker or dask_scheduler).periodic_callbacks
        return {"tick": "tick" in pcs and pcs["tick"].is_running(),  # taken out of the list, or stopped
                **({"memory_monitor": pcs["memory_monitor"].callback_time} if "memory_monitor" in pcs else {})}

    with farm.client() as c:
        for timers in [*c.run(_timers).values(), *c.run(_timers, nanny=True).values(), c.run_on_scheduler(_timers)]:
            assert timers["tick"] is False, timers
            assert timers.get("memory_monitor", 1000.0) >= 1000.0, timers


def _farm_counters(farm: Farm) -> dict[str, int]:
    from puppet.batch.worker import counters

    with farm.client() as c:
        per_worker = c.run(counters)
    return {k: sum(w[k] for w in per_worker.values()) for k in next(iter(per_worker.values()))}


def test_one_simulation_for_pc2_and_mp4_equal_single_exports(farm: Farm, tmp_path: Path,
                                                              capsys: pytest.CaptureFixture) -> None:
    import imageio.v2 as imageio

    takes = [write_take(tmp_path / "s" / f"both{k}.jsonl", ticks=40, seed=30 + k) for k in range(3)]
    out = tmp_path / "out"
    out.mkdir()
    before = _farm_counters(farm)
    assert main(["batch", "export", str(tmp_path / "s"), "--out", str(out), "--to", "pc2,mp4", "--size", "160x96",
                 "--scheduler", farm.address]) == 0
    assert "(3 tasks)" in capsys.readouterr().out  # one task per take, for both formats
    after = _farm_counters(farm)
    assert after["simulator_copies"] - before["simulator_copies"] == 3  # one simulation per take
    assert after["face_loads"] + after["face_hits"] - before["face_loads"] - before["face_hits"] == 3
    assert after["simulators_built"] - before["simulators_built"] <= 2  # at most once per worker
    for t in takes:
        assert (out / (t.stem + ".pc2")).read_bytes() == replay_out(t, tmp_path / (t.stem + ".pc2"))
        single = replay_out(t, tmp_path / (t.stem + ".mp4"), "--size", "160x96")
        got = [f for f in imageio.get_reader(str(out / (t.stem + ".mp4")))]
        want = [f for f in imageio.get_reader(str(tmp_path / (t.stem + ".mp4")))]
        assert len(got) == len(want) == 20 and all(np.array_equal(g, w) for g, w in zip(got, want))
        assert (out / (t.stem + ".mp4")).read_bytes() == single


def test_library_query_selection_and_recognize(farm: Farm, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    lib = tmp_path / "takes.db"
    a = write_take(tmp_path / "s" / "ana.jsonl", ticks=40, seed=4, performer="ana")
    b = write_take(tmp_path / "s" / "bob.jsonl", ticks=40, seed=5, performer="bob")
    with Library(lib) as library:
        library.register(a)
        library.register(b)
    out = tmp_path / "out"
    out.mkdir()
    assert main(["batch", "recognize", "performer:bob", "--library", str(lib), "--out", str(out),
                 "--scheduler", farm.address]) == 0
    capsys.readouterr()
    assert sorted(p.name for p in out.iterdir() if p.is_file()) == ["bob.expressions.json"]
    assert main(["recognize", str(b), "--json"]) == 0
    single = json.loads(capsys.readouterr().out)
    assert single  # something was recognised
    assert json.loads((out / "bob.expressions.json").read_text()) == single
    # the library's takes get the spans, as `puppet takes check` would store them; ana's is untouched
    with Library(lib) as library:
        ids = {t["performer"]: t["id"] for t in library.search("")}
        stored = library.get(ids["bob"])["expressions"]
        assert library.get(ids["ana"])["expressions"] == []
        assert [t["id"] for t in library.search(f"expression:{single[0]['expression']}")] == [ids["bob"]]
    assert [(s["start"], s["end"], s["expression"]) for s in stored] == \
        [(s["start"], s["end"], s["expression"]) for s in single]
    assert all(s["score"] == w["scores"][w["expression"]] for s, w in zip(stored, single))


KILL_TICKS = 420


def test_worker_killed_mid_batch(farm: Farm, tmp_path: Path) -> None:
    shoot = tmp_path / "shoot"
    takes = [write_take(shoot / f"long{k}.jsonl", ticks=KILL_TICKS, seed=20 + k) for k in range(4)]
    out = tmp_path / "out"
    out.mkdir()
    batch = subprocess.Popen([sys.executable, "-m", "puppet", "batch", "export", str(shoot), "--out", str(out),
                              "--to", "pc2", "--scheduler", farm.address], stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True)
    killed = None
    with farm.client() as c:
        deadline = time.monotonic() + 300  # a loaded machine may take minutes to start the batch's client
        while killed is None and time.monotonic() < deadline and batch.poll() is None:
            busy = {w: keys for w, keys in c.processing().items() if any(str(k).startswith("export-") for k in keys)}
            if busy:
                time.sleep(0.5)  # well inside the task (each lasts seconds)
                worker = sorted(busy)[0]
                pid = c.run(os.getpid, workers=[worker])[worker]
                os.kill(pid, signal.SIGKILL)
                killed = worker
            time.sleep(0.05)
    stdout, stderr = batch.communicate(timeout=300)
    assert killed is not None, "no task was seen running"
    assert batch.returncode == 0, stderr
    assert "wrote 8 files" in stdout, stdout
    for t in takes:
        assert (out / (t.stem + ".pc2")).read_bytes() == replay_out(t, tmp_path / (t.stem + ".pc2")), t.stem
    assert not [p.name for p in out.iterdir() if p.name.startswith(".") and ".part" in p.name]  # no half files
    farm.wait_for_workers(2)  # the nanny brought the killed worker back


def test_a_worker_joining_after_a_batch_started_is_quiet_too(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """A worker added to the farm (or restarted by its nanny) after the batch's plugins were
    registered keeps neither Dask's stack sampler nor its 20 ms tick: both would take CPU from the
    frames of every take it runs."""
    from farm import WORKER_ARGS

    def diagnostics_running(dask_worker=None) -> list[str]:  # type: ignore[no-untyped-def]  # sent by value
        return sorted(k for k, pc in dask_worker.periodic_callbacks.items()
                      if k in ("tick", "profile", "profile-cycle") and pc.is_running())

    (tmp_path / "farm").mkdir()
    f = Farm(tmp_path / "farm", workers=1)
    try:
        take = write_take(tmp_path / "s" / "one.jsonl", ticks=20, seed=3)
        assert main(["batch", "export", str(take), "--out", str(tmp_path), "--to", "csv", "--scheduler", f.address]) == 0
        f.procs.append(f._spawn("late", "worker", "--scheduler-file", str(f.file), *WORKER_ARGS))
        f.wait_for_workers(2)
        assert main(["batch", "export", str(take), "--out", str(tmp_path), "--to", "csv", "--force",
                     "--scheduler", f.address]) == 0
        capsys.readouterr()
        with f.client() as c:
            assert c.run(diagnostics_running) == {w: [] for w in c.scheduler_info()["workers"]}
            assert all(v == [] for v in c.run(diagnostics_running, nanny=True).values())
    finally:
        f.stop()


@pytest.fixture
def in_this_process() -> Iterator[None]:
    """Jobs run here (as on a worker) install the worker's caches: undone afterwards."""
    from puppet import replay
    from puppet.batch import worker

    try:
        yield
    finally:
        replay.use_loaders()
        worker.clear()


def test_a_worker_that_cannot_see_the_output_folder_sends_the_bytes(tmp_path: Path, in_this_process: None) -> None:
    from puppet.batch import jobs
    from puppet.batch.plan import reach_token, reachable

    take = write_take(tmp_path / "s" / "far.jsonl", ticks=45, seed=12)
    out = tmp_path / "out"
    out.mkdir()
    dest = reach_token(out)
    assert reachable(dest) == out.resolve()
    elsewhere = dict(dest, token="0" * 32)  # another machine's folder of the same name
    assert reachable(elsewhere) is None
    got = jobs.export_outputs({take.name: take.read_bytes()}, str(take),
                              [("far.pc2", {"fps": None}), ("far.csv", {"fps": None})], elsewhere)
    assert not (out / "far.pc2").exists()
    for name in ("far.pc2", "far.csv"):
        want = replay_out(take, tmp_path / name)
        assert got[name][name] == want
    assert got["far.pc2"]["far.obj"] == (tmp_path / "far.obj").read_bytes()
    here = jobs.export_outputs({take.name: take.read_bytes()}, str(take), [("far.pc2", {"fps": None})], dest)
    assert (out / "far.pc2").read_bytes() == got["far.pc2"]["far.pc2"]  # written in place
    assert here["far.pc2"] == {"far.pc2": jobs.IN_PLACE, "far.obj": jobs.IN_PLACE}  # names only travel back


def test_long_video_in_chunks_equals_single_export(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    import imageio.v2 as imageio

    take = write_take(tmp_path / "s" / "clip.jsonl", ticks=70, seed=7)
    out = tmp_path / "out"
    out.mkdir()
    # the local cluster (no --scheduler): 35 frames in 4 chunks of at most 10
    assert main(["batch", "export", str(take), "--out", str(out), "--to", "mp4", "--size", "160x96",
                 "--chunk-frames", "10", "--workers", "2"]) == 0
    assert "(6 tasks)" in capsys.readouterr().out  # checkpoints, 4 chunks, the join
    single = replay_out(take, tmp_path / "single.mp4", "--size", "160x96")
    got = [f for f in imageio.get_reader(str(out / "clip.mp4"))]
    want = [f for f in imageio.get_reader(str(tmp_path / "single.mp4"))]
    assert len(got) == len(want) == 35
    assert all(np.array_equal(g, w) for g, w in zip(got, want))
    assert np.abs(want[0].astype(int) - want[-1].astype(int)).mean() > 0.05  # the face moved
    assert (out / "clip.mp4").read_bytes() == single


def test_batch_fit_equals_fit(farm: Farm, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    from puppet.session import read_session

    take = write_take(tmp_path / "s" / "phone.jsonl", ticks=40, seed=11)
    caps = tmp_path / "caps"
    caps.mkdir()
    assert main(["batch", "export", str(take), "--out", str(caps), "--to", "arkit", "--scheduler", farm.address]) == 0
    out = tmp_path / "fitted"
    out.mkdir()
    assert main(["batch", "fit", str(caps), "--out", str(out), "--scheduler", farm.address]) == 0
    assert main(["fit", str(caps / "phone.arkit.csv"), "--out", str(tmp_path / "single.jsonl")]) == 0
    capsys.readouterr()
    got, want = read_session(out / "phone.jsonl"), read_session(tmp_path / "single.jsonl")
    assert got.ticks == want.ticks > 0 and got.values == want.values
    assert got.header["source"] == want.header["source"]  # names the user's capture, not a worker's copy


@pytest.mark.parametrize("frames,size", [(1, 10), (10, 10), (11, 10), (35, 10), (1801, 1800), (5, 0)])
def test_chunks_cover_every_frame_once(frames: int, size: int) -> None:
    from puppet.batch.plan import chunks

    parts = chunks(frames, size)
    assert parts[0][0] == 0 and parts[-1][1] == frames
    assert all(a < b and (size <= 0 or b - a <= size) for a, b in parts)
    assert all(parts[k][1] == parts[k + 1][0] for k in range(len(parts) - 1))
    assert len(parts) == (1 if size <= 0 else -(-frames // size))


def _puppet(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    """The `puppet` command in a process of its own, as a user runs it."""
    return subprocess.run([sys.executable, "-m", "puppet", *args], cwd=cwd, capture_output=True, text=True,
                          timeout=300)


def test_recorded_takes_imported_searched_and_exported_through_the_farm(farm: Farm, tmp_path: Path) -> None:
    """The whole flow from outside: takes recorded by `puppet live --record`, a folder imported into
    the library, a search, and `puppet batch export QUERY` through the farm, a damaged and a cut-off
    take among them; each output equals `puppet replay --out`'s."""
    script = Path(__file__).resolve().parents[2] / "examples" / "mock" / "sgi_rehearsal.toml"
    lib = str(tmp_path / "takes.db")
    shoot = tmp_path / "shoot"
    shoot.mkdir()
    for name, who in (("day1", "ana"), ("day2", "bob")):
        r = _puppet("live", "--headless", "--no-panel", "--device", f"mock://{script}", "--duration", "1",
                    "--tick-rate", "60", "--record", f"shoot/{name}.jsonl", "--performer", who,
                    "--library", str(tmp_path / "other.db"), cwd=tmp_path)
        assert r.returncode == 0, r.stderr[-800:]
    lines = (shoot / "day1.jsonl").read_text().splitlines(keepends=True)
    (shoot / "cut.jsonl").write_text("".join(lines[: len(lines) // 2]) + lines[len(lines) // 2][:15])
    (shoot / "bad.jsonl").write_text("this is not a take\n")
    r = _puppet("takes", "import", "shoot", "--library", lib, cwd=tmp_path)
    assert r.returncode == 0 and "registered 3 takes" in r.stdout, r.stdout + r.stderr
    assert "bad.jsonl" in r.stdout + r.stderr
    r = _puppet("takes", "search", "performer:ana", "--library", lib, "--json", cwd=tmp_path)
    assert sorted(Path(t["path"]).name for t in json.loads(r.stdout)) == ["cut.jsonl", "day1.jsonl"]

    r = _puppet("batch", "export", "performer:ana", "shoot/bad.jsonl", "--library", lib, "--out", "out",
                "--to", "pc2,csv", "--scheduler", farm.address, cwd=tmp_path)
    assert r.returncode == 2, r.stderr[-800:]
    failed = [line for line in r.stderr.splitlines() if line.startswith("puppet: failed:")]
    assert len(failed) == 1 and str(shoot / "bad.jsonl") in failed[0], r.stderr[-800:]
    assert any("cut off" in line and str(shoot / "cut.jsonl") in line for line in r.stderr.splitlines()
               if line.startswith("puppet: warning:")), r.stderr[-800:]  # as `puppet replay` warns
    assert "wrote 6 files" in r.stdout and "1 input failed" in r.stdout, r.stdout
    (tmp_path / "single").mkdir()
    for stem in ("day1", "cut"):
        for suffix in (".pc2", ".obj", ".csv"):
            if suffix != ".obj":
                assert _puppet("replay", f"shoot/{stem}.jsonl", "--out", f"single/{stem}{suffix}",
                               cwd=tmp_path).returncode == 0
            assert (tmp_path / "out" / (stem + suffix)).read_bytes() == \
                (tmp_path / "single" / (stem + suffix)).read_bytes(), stem + suffix
    assert not (tmp_path / "out" / "day2.pc2").exists()


def test_an_unreachable_scheduler_is_one_line(tmp_path: Path, capsys: pytest.CaptureFixture,
                                              monkeypatch: pytest.MonkeyPatch) -> None:
    import socket

    from puppet.batch import run

    monkeypatch.setattr(run, "CONNECT_TIMEOUT", 1.0)
    with socket.socket() as s:  # a port nothing listens on any more
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    take = write_take(tmp_path / "t.jsonl", ticks=10)
    assert main(["batch", "export", str(take), "--out", str(tmp_path), "--to", "csv",
                 "--scheduler", f"tcp://127.0.0.1:{port}"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"127.0.0.1:{port}" in err[0] and "dask scheduler" in err[0], err
    assert not (tmp_path / "t.csv").exists()


def test_half_written_outputs_are_removed_and_nothing_else(tmp_path: Path) -> None:
    """What a worker killed mid-write leaves (safefile's hidden `.STEM.*.part*` temporaries of this
    batch's outputs) goes when the batch ends; the outputs, other files and other batches' halves stay."""
    from puppet.batch.plan import Input, Output
    from puppet.batch.run import _remove_parts
    from safefile import atomic_write

    todo = [Output(Input(tmp_path / f"{s}.jsonl"), "export", f"{s}{x}", "key", {})
            for s in ("take1", "take.2") for x in (".pc2", ".arkit.csv")]
    for o in todo:
        with atomic_write(tmp_path / o.name, "wb") as fh:
            fh.write(b"whole")
    halves = [".take1.k3j_x.part.pc2", ".take1.q8.part.obj", ".take.2.arkit.zz1.part.csv", ".take.2.a.part"]
    kept = [".take10.k3j_x.part.pc2", ".other.a1.part.pc2", "take1.part.pc2", ".take1.pc2", "notes.txt"]
    for name in halves + kept:
        (tmp_path / name).write_bytes(b"half")
    _remove_parts(tmp_path, todo)
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(kept + [o.name for o in todo])


def test_a_query_matching_nothing_names_the_library(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """Recordings go to the library of the show that made them: a query that finds nothing says
    which library it searched, so a user looking in the wrong one sees it."""
    lib = tmp_path / "mine.db"
    write_take(tmp_path / "a.jsonl", seed=1, performer="ana")
    assert main(["takes", "import", str(tmp_path), "--library", str(lib)]) == 0
    capsys.readouterr()
    assert main(["batch", "export", "performer:bob", "--library", str(lib), "--out", str(tmp_path / "o")]) == 2
    _, err = capsys.readouterr()
    assert err.count("\n") == 1 and str(lib) in err and "performer:bob" in err, err


def test_out_naming_a_file_is_one_line(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    take = tmp_path / "a.jsonl"
    write_take(take, seed=1)
    (tmp_path / "renders").write_text("a file where the folder should be\n")
    out = tmp_path / "renders"
    assert main(["batch", "export", str(take), "--out", str(out), "--to", "csv", "--workers", "1"]) == 2
    _, err = capsys.readouterr()
    assert err.count("\n") == 1 and "not a folder" in err, err


def test_a_header_only_take_fails_naming_the_users_file(tmp_path: Path, in_this_process: None) -> None:
    """A take killed after its header, in a batch: the failure names the user's file, not the
    private copy a task reads (a temporary folder gone by the time the user reads the line)."""
    from puppet.batch import jobs

    take = write_take(tmp_path / "s" / "short.jsonl", ticks=45, seed=3)
    empty = tmp_path / "s" / "empty.jsonl"
    empty.write_bytes(take.read_bytes().split(b"\n", 1)[0] + b"\n")
    with pytest.raises(jobs.JobFailed) as err:
        jobs.export_outputs({empty.name: empty.read_bytes()}, str(empty), [("empty.csv", {"fps": None})], None)
    assert str(err.value).startswith(f"{empty} holds no performance"), err.value
    assert "puppet-batch-" not in str(err.value)


def test_an_unclosed_ipv6_scheduler_and_a_runaway_worker_count_are_one_line(tmp_path: Path,
                                                                          capsys: pytest.CaptureFixture) -> None:
    """`--scheduler tcp://[::1` was urllib's 'Invalid IPv6 URL' traceback; `--workers 100000` began
    starting a hundred thousand worker processes. Both are one line, exit 2, before anything runs."""
    take = tmp_path / "a.jsonl"
    write_take(take, seed=1)
    out = tmp_path / "out"
    for extra in (["--scheduler", "tcp://[::1"], ["--scheduler", "[::1:8786"], ["--workers", "100000"]):
        assert main(["batch", "export", str(take), "--out", str(out), "--to", "csv", *extra]) == 2
        _, err = capsys.readouterr()
        assert err.count("\n") == 1 and extra[0] in err, (extra, err)
    assert not out.exists()


def test_a_folder_of_voices_is_fitted_but_a_takes_sound_is_not(tmp_path: Path) -> None:
    """`puppet fit speech.wav` fits a voice, and `batch fit speech.wav` did too, but `batch fit
    FOLDER` left every WAV out without a word. A WAV alone is a voice to fit; `take.wav` beside
    `take.jsonl` (a show's microphone) is the take's sound, not a capture."""
    from puppet.batch.plan import select
    from puppet.batch.run import SUFFIXES

    (tmp_path / "voices").mkdir()
    for name in ("voices/vowels.wav", "voices/Hum.WAV", "show.wav", "show.jsonl", "notes.txt"):
        (tmp_path / name).write_bytes(b"RIFF")
    got = sorted(p.relative_to(tmp_path).as_posix() for p in select([str(tmp_path)], None, SUFFIXES["fit"]))
    assert got == ["voices/Hum.WAV", "voices/vowels.wav"]
    assert [p.name for p in select([str(tmp_path / "show.wav")], None, SUFFIXES["fit"])] == ["show.wav"]


def test_drawing_options_on_data_kinds_are_said_not_to_apply(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """`--to csv --view wireframe` dropped the view without a word, as `puppet replay` did."""
    take = tmp_path / "a.jsonl"
    write_take(take, seed=2)
    plain, drawn = tmp_path / "plain", tmp_path / "drawn"
    assert main(["batch", "export", str(take), "--out", str(plain), "--to", "csv", "--workers", "1"]) == 0
    assert "note" not in capsys.readouterr().err
    assert main(["batch", "export", str(take), "--out", str(drawn), "--to", "csv", "--workers", "1",
                 "--view", "wireframe", "--size", "320x240"]) == 0
    err = [line for line in capsys.readouterr().err.splitlines() if "note" in line]
    assert err == ["puppet: note: --view and --size do not apply to --to csv (only mp4 is drawn); ignored"], err
    assert (drawn / "a.csv").read_bytes() == (plain / "a.csv").read_bytes()
