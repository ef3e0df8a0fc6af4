"""Batch and page export names: an output is named after its input without the input's own suffix,
so two takes the product itself keeps side by side never share an output."""

from __future__ import annotations

from pathlib import Path

from puppet.batch.plan import Input, output_names, output_stem


def _inputs(*names: str) -> list[Input]:
    return [Input(Path("/shoot") / n, digest=f"{k:02d}" * 32) for k, n in enumerate(names)]


def test_a_kept_earlier_take_gets_its_own_outputs() -> None:
    # recording to show.jsonl again keeps the earlier take as show.1.jsonl (session.keep_previous):
    # its outputs must not take over show.mp4, which the current take's own export is called
    names = output_names(_inputs("show.jsonl", "show.1.jsonl", "scene2.take3.jsonl"), ".mp4")
    assert names == ["show.mp4", "show.1.mp4", "scene2.take3.mp4"]


def test_an_exported_capture_fits_back_to_its_take_name() -> None:
    assert output_names(_inputs("phone.arkit.csv", "dots.csv", "cap.c3d"), ".jsonl") == \
        ["phone.jsonl", "dots.jsonl", "cap.jsonl"]
    assert output_stem(Path("Show.JSONL")) == "Show"


def test_inputs_sharing_a_name_in_two_folders_are_told_apart() -> None:
    items = [Input(Path("/day1/take.jsonl"), digest="a" * 64), Input(Path("/day2/take.jsonl"), digest="b" * 64)]
    assert output_names(items, ".pc2") == ["take-aaaaaaaa.pc2", "take-bbbbbbbb.pc2"]


def test_the_page_exports_a_kept_take_beside_it_under_its_own_name(tmp_path: Path) -> None:
    import asyncio
    import sys

    from aiohttp import web
    from aiohttp.test_utils import TestClient, TestServer

    sys.path.insert(0, str(Path(__file__).parent))
    from takes import write_take

    from puppet.library.store import Library
    from puppet.panel.takes import TakeRoutes

    current = write_take(tmp_path / "show.jsonl", ticks=20, seed=1)
    kept = write_take(tmp_path / "show.1.jsonl", ticks=30, seed=2)
    lib_path = tmp_path / "takes.db"
    with Library(lib_path) as lib:
        lib.register(current)
        kept_id = lib.register(kept)

    async def export() -> dict:
        app = web.Application()
        TakeRoutes(lambda: lib_path).add(app)
        async with TestClient(TestServer(app, host="127.0.0.1")) as client:
            started = await (await client.post(f"/api/takes/{kept_id}/export?to=csv")).json()
            for _ in range(600):
                jobs = (await (await client.get("/api/takes/exports")).json())["exports"]
                if jobs and jobs[-1]["state"] != "running":
                    return {"started": started, "job": jobs[-1]}
                await asyncio.sleep(0.1)
        raise AssertionError("the export did not finish")

    done = asyncio.run(export())
    assert done["job"]["state"] == "done", done
    assert done["started"]["out"] == str(tmp_path / "show.1.csv")
    assert (tmp_path / "show.1.csv").is_file() and not (tmp_path / "show.csv").exists()


def test_a_negative_chunk_length_is_one_line(tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    from puppet.cli import main

    take = tmp_path / "a.jsonl"
    take.write_text("")
    assert main(["batch", "export", str(take), "--out", str(tmp_path / "out"), "--chunk-frames", "-5"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--chunk-frames" in err, err
    assert not (tmp_path / "out").exists()  # refused before anything started


def test_a_folder_for_recognize_leaves_out_the_takes_own_channel_exports(tmp_path: Path) -> None:
    # `puppet replay take.jsonl --out take.csv` (or the page's csv button) writes the channels beside
    # the take: not a capture, so a folder's recognize or fit must not fail on it
    from puppet.batch.plan import select
    from puppet.batch.run import SUFFIXES

    (tmp_path / "take.jsonl").write_text("{}\n")
    (tmp_path / "take.csv").write_text("frame,time,tick,jaw\n0,0.0,0,0.5\n")
    (tmp_path / "dots.csv").write_text("time,nose_x,nose_y,nose_z\n0.0,1,2,3\n")
    for action, want in (("recognize", ["dots.csv", "take.jsonl"]), ("fit", ["dots.csv"])):
        assert sorted(p.name for p in select([str(tmp_path)], None, SUFFIXES[action])) == want, action
    # named on its own, a file is taken as given (and fails with its reason)
    assert [p.name for p in select([str(tmp_path / "take.csv")], None, SUFFIXES["fit"])] == ["take.csv"]


def test_a_library_query_leaves_out_a_take_a_show_is_recording(tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    """A take a show is still recording has no end yet: the batch leaves it out and says so, and
    takes the rest; once its show has died (the lock gone) it is taken as far as the file goes."""
    import fcntl
    import os

    from puppet.batch.plan import select
    from puppet.library.store import Library
    from puppet.session import read_session
    from takes import write_take

    lib = tmp_path / "takes.db"
    done = write_take(tmp_path / "done.jsonl", ticks=30, seed=1)
    live = write_take(tmp_path / "live.jsonl", ticks=30, seed=2)
    with Library(lib) as library:
        library.register(done)
        library.begin(live, read_session(live).header, performer="ana")
    fd = os.open(live, os.O_RDONLY)  # the recording's lock, as the show holds it
    fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    try:
        chosen = select(["missing:no"], str(lib), (".jsonl",))
    finally:
        os.close(fd)
    assert chosen == [done.resolve()]
    assert "is being recorded by a show; left out" in capsys.readouterr().err
    assert sorted(select(["missing:no"], str(lib), (".jsonl",))) == sorted([done.resolve(), live.resolve()])


def test_the_page_shows_a_take_being_recorded_and_does_not_export_it(tmp_path: Path) -> None:
    """The page's list says which take a show is recording (and, once the show is gone, completes
    its entry from the file); exporting a take still being recorded is refused with a reason."""
    import asyncio
    import fcntl
    import os

    import pytest
    from aiohttp import web
    from aiohttp.test_utils import TestClient, TestServer
    from takes import write_take

    from puppet.library.store import Library
    from puppet.panel.takes import TakeRoutes
    from puppet.session import read_session

    live = write_take(tmp_path / "live.jsonl", ticks=30, seed=2)
    lib_path = tmp_path / "takes.db"
    with Library(lib_path) as lib:
        take_id = lib.begin(live, read_session(live).header)

    async def page() -> tuple[dict, dict]:
        app = web.Application()
        TakeRoutes(lambda: lib_path).add(app)
        async with TestClient(TestServer(app, host="127.0.0.1")) as client:
            listed = await (await client.get("/api/takes")).json()
            export = await (await client.post(f"/api/takes/{take_id}/export?to=csv")).json()
            return listed, export

    fd = os.open(live, os.O_RDONLY)  # the recording's lock, as the show holds it
    fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    try:
        listed, export = asyncio.run(page())
    finally:
        os.close(fd)
    assert [t["state"] for t in listed["takes"]] == ["recording"]
    assert not export["ok"] and "being recorded by a show" in export["error"]
    assert not (tmp_path / "live.csv").exists()
    listed, export = asyncio.run(page())  # the show gone: completed from the file (its end is there), exported
    assert [t["state"] for t in listed["takes"]] == ["complete"] and export["ok"]
    assert listed["takes"][0]["duration"] == pytest.approx(read_session(live).duration)
