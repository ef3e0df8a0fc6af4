"""`puppet fit` and `puppet recognize` end to end, in-process: every input format, the take that
replays exactly, the --json contract, and damaged files (one line, exit 2, nothing written)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from fitdata import correspond, damaged_texts, rotation, write_landmark_csv

from puppet.cli import main
from sim.fit.basis import preset_values

# the performance: 10 frames at rest, happiness 0.8 held for 20, surprise 0.7 held for 20, at 30 fps
SCRIPT = [(None, 10), (("happiness", 0.8), 20), (("surprise", 0.7), 20)]
FPS = 30.0


@pytest.fixture(scope="module")
def performance(res1, face0, basis0):  # type: ignore[no-untyped-def]
    """(times, rig landmark names, (T, P, 3) res-1 positions at the res-0 landmarks)."""
    mesh0 = face0.model.mesh
    names = sorted(mesh0.landmarks)
    near = correspond(face0.model, res1.model, np.array([mesh0.landmarks[n] for n in names]))
    frames = []
    for what, n in SCRIPT:
        pos = res1.rest if what is None else res1.pose(res1.values_for(preset_values(*what)))
        frames += [pos[near]] * n
    pts = np.array(frames)
    return np.arange(len(pts)) / FPS, names, pts


def _moved(pts: np.ndarray) -> np.ndarray:
    """Millimetres, a turning head, somewhere in the room."""
    k = np.arange(len(pts))[:, None, None]
    out = np.empty_like(pts)
    for i in range(len(pts)):
        out[i] = 10.0 * pts[i] @ rotation(0.01 * i, 0.15, -0.05).T + np.array([100.0, 1500.0, -40.0])
    return out + 0.0 * k


def _one_line_exit_2(capsys: pytest.CaptureFixture[str], argv: list[str], path: Path) -> str:
    code = main(argv)
    err = capsys.readouterr().err.strip()
    assert code == 2, err
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    assert not path.exists()
    return err


def _take_values(path: Path, face0) -> tuple[list[str], np.ndarray]:  # type: ignore[no-untyped-def]
    from puppet.session import read_session

    s = read_session(path)
    names = [c.name for c in face0.vocab.channels]
    return names, s.value_array(np.array(face0.vocab.defaults()), names)


def test_landmark_csv_becomes_a_take_that_replays_exactly(tmp_path, performance, face0, capsys) -> None:  # type: ignore[no-untyped-def]
    times, names, pts = performance
    csv_path = tmp_path / "track.csv"
    write_landmark_csv(csv_path, times, _moved(pts), names)
    take, report = tmp_path / "take.jsonl", tmp_path / "report.csv"
    assert main(["fit", str(csv_path), "--out", str(take), "--report", str(report)]) == 0
    out = capsys.readouterr().out
    assert "scale 0.1" in out and "residual" in out
    rows = report.read_text().splitlines()
    assert rows[0].startswith("time,residual_mm") and len(rows) == len(times) + 1
    chans, values = _take_values(take, face0)
    tick = lambda t: int(round(t * 60))  # noqa: E731
    smile = values[tick(20 / FPS)]
    assert smile[chans.index("zygomaticus_major_l")] == pytest.approx(0.8, abs=0.25)
    assert smile[chans.index("frontalis_inner_l")] < 0.1
    brow = values[tick(42 / FPS)]
    assert brow[chans.index("frontalis_inner_l")] == pytest.approx(0.7, abs=0.25)
    assert brow[chans.index("zygomaticus_major_l")] < 0.1
    assert main(["replay", str(take), "--headless"]) == 0
    assert "bit-identical to the live session at 1 checkpoints" in capsys.readouterr().out


def test_fit_writes_curves_that_play(tmp_path, performance, capsys) -> None:  # type: ignore[no-untyped-def]
    times, names, pts = performance
    csv_path = tmp_path / "track.csv"
    write_landmark_csv(csv_path, times, pts, names)
    curves = tmp_path / "fit.curves"
    assert main(["fit", str(csv_path), "--out", str(curves), "--no-relinearise"]) == 0
    text = curves.read_text()
    assert text.startswith("facepuppet-curves 1") and "zygomaticus_major" in text
    assert main(["replay", "--curves", str(curves), "--headless"]) == 0


def test_recognize_prints_spans_with_every_score(tmp_path, performance, capsys) -> None:  # type: ignore[no-untyped-def]
    from sim.facs import EXPRESSIONS

    times, names, pts = performance
    csv_path = tmp_path / "track.csv"
    write_landmark_csv(csv_path, times, _moved(pts), names)
    capsys.readouterr()
    assert main(["recognize", str(csv_path), "--json"]) == 0
    spans = json.loads(capsys.readouterr().out)
    assert [s["expression"] for s in spans] == ["neutral", "happiness", "surprise"]
    for s in spans:
        assert set(s) == {"start", "end", "expression", "scores"}  # the contract's keys, no more
        assert set(s["scores"]) == {*EXPRESSIONS, "neutral"}
    assert main(["recognize", str(csv_path), "--json", "--by", "activations"]) == 0
    by_acts = json.loads(capsys.readouterr().out)
    assert [s["expression"] for s in by_acts] == [s["expression"] for s in spans]
    assert [(s["start"], s["end"]) for s in by_acts] == [(s["start"], s["end"]) for s in spans]
    assert spans[1]["start"] == pytest.approx(10 / FPS, abs=0.1)
    assert main(["recognize", str(csv_path)]) == 0
    assert "happiness" in capsys.readouterr().out


def test_recognize_a_take(tmp_path, face0, capsys) -> None:  # type: ignore[no-untyped-def]
    from puppet.capture.take import write_take

    names = [c.name for c in face0.vocab.channels]
    values = np.tile(np.array(face0.vocab.defaults()), (120, 1))
    for ch, v in preset_values("sadness", 0.8).items():
        values[50:, names.index(ch)] = v
    take = tmp_path / "sad.jsonl"
    write_take(take, face0, values, 60.0, {"test": True})
    capsys.readouterr()
    assert main(["recognize", str(take), "--json"]) == 0
    spans = json.loads(capsys.readouterr().out)
    assert [s["expression"] for s in spans] == ["neutral", "sadness"]


def test_recognize_a_take_of_one_tick(tmp_path, face0, capsys) -> None:  # type: ignore[no-untyped-def]
    """A take of one tick (a show stopped at once): recognize simulated none of its ~30 frames a
    second and ended in a ValueError traceback. It reads the take at its own rate: one span."""
    from puppet.capture.take import write_take

    take = tmp_path / "blink.jsonl"
    write_take(take, face0, np.array([face0.vocab.defaults()]), 60.0, {"test": True})
    capsys.readouterr()
    assert main(["recognize", str(take), "--json"]) == 0
    spans = json.loads(capsys.readouterr().out)
    assert [s["expression"] for s in spans] == ["neutral"]


def test_68_point_layout_through_the_shipped_correspondence(tmp_path, performance, capsys) -> None:  # type: ignore[no-untyped-def]
    from puppet.capture.points import load_correspondence

    times, names, pts = performance
    import sim.face

    mesh = sim.face.default_model(0).mesh
    corr = load_correspondence("ibug68", mesh)
    by_vertex = {mesh.landmarks[n]: i for i, n in enumerate(names)}
    ids = list(corr)
    cols = np.stack([pts[:, by_vertex[corr[k]]] for k in ids], axis=1)
    extra = pts[:, :3] + 5.0  # points the layout has but the correspondence does not map
    csv_path = tmp_path / "ibug.csv"
    write_landmark_csv(csv_path, times, np.concatenate([cols, extra], axis=1), ids + ["60", "61", "63"])
    take = tmp_path / "t.jsonl"
    assert main(["fit", str(csv_path), "--map", "ibug68", "--out", str(take)]) == 0
    assert "3 input points not in the correspondence were ignored" in capsys.readouterr().out
    err = _one_line_exit_2(capsys, ["fit", str(csv_path), "--out", str(tmp_path / "u.jsonl")], tmp_path / "u.jsonl")
    assert "not a rig landmark" in err


def _write_c3d(path: Path, labels: list[str], pts: np.ndarray, rate: float) -> None:
    import c3d

    w = c3d.Writer(point_rate=rate)
    frames = []
    for f in pts:
        p = np.zeros((len(labels), 5), np.float32)
        p[:, :3] = f
        frames.append((p, np.zeros((0, 0), np.float32)))
    frames[3][0][2, 3] = -1.0  # one occluded sample
    w.add_frames(frames)
    w.set_point_labels(labels)
    with open(path, "wb") as fh:
        w.write(fh)


@pytest.mark.filterwarnings("ignore:No analog data")
def test_c3d_markers(tmp_path, performance, capsys) -> None:  # type: ignore[no-untyped-def]
    times, names, pts = performance
    path = tmp_path / "markers.c3d"
    _write_c3d(path, names, _moved(pts), FPS)
    take = tmp_path / "c3d.jsonl"
    assert main(["fit", str(path), "--out", str(take), "--no-relinearise"]) == 0
    assert "1 occluded marker samples filled" in capsys.readouterr().out
    bad = tmp_path / "bad.c3d"
    bad.write_bytes(path.read_bytes()[:700])
    _one_line_exit_2(capsys, ["fit", str(bad), "--out", str(tmp_path / "x.jsonl")], tmp_path / "x.jsonl")
    wrong = tmp_path / "wrong.c3d"
    _write_c3d(wrong, [n + "X" for n in names], pts, FPS)
    err = _one_line_exit_2(capsys, ["fit", str(wrong), "--out", str(tmp_path / "y.jsonl")], tmp_path / "y.jsonl")
    assert "not a rig landmark" in err


def test_point_cache_from_the_other_integrator(tmp_path, face0, basis0, capsys) -> None:  # type: ignore[no-untyped-def]
    import sim.face
    from puppet.export.pc2 import PC2Writer, write_obj

    settler, basis, _ = basis0
    model = face0.model
    s = sim.Simulator(model, 1 / 60.0, wrinkles=False, method="implicit")
    c = sim.FaceControl(model)
    state = settler.rest_state.copy()
    path = tmp_path / "other.pc2"
    w = PC2Writer(path, model.n_vertices)
    truth = preset_values("anger", 0.7)
    for k in range(90):
        if k == 20:
            for ch, v in truth.items():
                c.set(ch, v)
        s.step(state, c)
        w.add(state.positions)
    w.close()
    write_obj(path.with_suffix(".obj"), model.rest, model.triangles)
    take = tmp_path / "pc2.jsonl"
    capsys.readouterr()
    assert main(["fit", str(path), "--out", str(take), "--no-relinearise"]) == 0
    chans, values = _take_values(take, face0)
    # anger's light upper-lid raise (AU5 0.3, levator 0.21) works against its lid tightener (AU7) on
    # the same lid: from positions alone the pair's net pull is what is seen, so only the channels
    # that carry the expression (>= 0.3) are held to their values; the lower lid's tightener (AU7)
    # moves a strip of lid skin a few mm (its basis column a sixteenth of the largest), which the
    # fit's sparsity prior leaves at 0 at this value
    for ch, v in truth.items():
        if v >= 0.3 and not ch.startswith("orbicularis_oculi_lower_lid"):
            assert values[85, chans.index(ch)] == pytest.approx(v, abs=0.2), ch
    path.with_suffix(".obj").write_text("v 0 0 0\n")
    err = _one_line_exit_2(capsys, ["fit", str(path), "--out", str(tmp_path / "z.jsonl")], tmp_path / "z.jsonl")
    assert "topology" in err
    path.with_suffix(".obj").unlink()
    _one_line_exit_2(capsys, ["fit", str(path), "--out", str(tmp_path / "z.jsonl")], tmp_path / "z.jsonl")
    write_obj(path.with_suffix(".obj"), model.rest, model.triangles)
    data = bytearray(path.read_bytes())
    data[40:44] = np.array([np.nan], "<f4").tobytes()
    path.write_bytes(bytes(data))
    err = _one_line_exit_2(capsys, ["fit", str(path), "--out", str(tmp_path / "z.jsonl")], tmp_path / "z.jsonl")
    assert "NaN" in err
    path.write_bytes(bytes(data[:1000]))
    _one_line_exit_2(capsys, ["fit", str(path), "--out", str(tmp_path / "z.jsonl")], tmp_path / "z.jsonl")


def test_the_scanned_heads_own_point_cache_is_read(tmp_path, capsys) -> None:  # type: ignore[no-untyped-def]
    """`puppet replay --out take.pc2` on the scanned head writes the whole scan (26,719 points in
    the scan's order); `puppet fit take.pc2` refused it ('26719 points, but the rig has 6020
    vertices'), though docs/fit.md names that export as a PC2 it reads. Its simulated skin's
    vertices are read out of it: each sample is the replayed state's surface."""
    from puppet.capture.pc2file import read_pc2_capture
    from puppet.export.pc2 import read_pc2
    from puppet.live import load_face, session_header
    from puppet.mapping.config import MappingSpec
    from puppet.replay import Replayer, build_performance
    from puppet.session import SessionWriter, read_session

    face = load_face(face="ict")
    names = [c.name for c in face.vocab.channels]
    take = tmp_path / "jaw.jsonl"
    header = session_header(face, MappingSpec(name="t", bindings=[], combine={}, source="t", text=""), 60.0, [])
    values = np.array(face.vocab.defaults())
    with SessionWriter(take, header, fsync_seconds=None) as w:
        for k in range(12):
            values[names.index("jaw")] = 0.05 * k
            w.values(k, values)
            w.tick(k + 1)
        w.close(12)
    cache = tmp_path / "jaw.pc2"
    assert main(["replay", str(take), "--out", str(cache)]) == 0
    assert read_pc2(cache)[0]["num_points"] == 26719 != face.model.n_vertices
    cap = read_pc2_capture(cache, face.model)
    rp = Replayer(build_performance(read_session(take), None, None))
    assert cap.points.shape == (12, face.model.n_vertices, 3)
    # the export lays lids that sank into the eyeballs back onto them, as drawn (sim.face.scan.lid_contact):
    # those few vertices around the eyes may lie off the simulated surface, by a fraction of a millimetre
    from puppet.export.scan import scan_dressing

    dressing = scan_dressing(face.model)
    lids = np.isin(dressing.skin, np.concatenate([e.band for e in dressing.lid_contact.eyes]))
    for k in range(12):
        rp.seek(k)  # sample k: the state after k ticks (the first sample is the rest)
        surface = np.asarray(rp.state.surface)
        assert np.allclose(cap.points[k][~lids], surface[~lids], atol=2e-4), k
        assert np.abs(cap.points[k][lids] - surface[lids]).max() < 0.05, k
    assert np.abs(cap.points[-1] - cap.points[0]).max() > 0.3  # the jaw opened
    cache.with_suffix(".obj").write_text("v 0 0 0\n")
    capsys.readouterr()
    assert "topology" in _one_line_exit_2(capsys, ["fit", str(cache), "--out", str(tmp_path / "z.jsonl")],
                                          tmp_path / "z.jsonl")


def test_arkit_csv_becomes_a_take_on_the_physical_face(tmp_path, face0, capsys) -> None:  # type: ignore[no-untyped-def]
    from puppet.export.arkit import ArkitCsvWriter

    names = [c.name for c in face0.vocab.channels]
    w = ArkitCsvWriter(tmp_path / "phone.arkit.csv", names, 60.0)
    values = np.tile(np.array(face0.vocab.defaults()), (90, 1))
    values[30:, names.index("zygomaticus_major_l")] = 0.385  # mouthSmile 0.7 (its span is 0.55: the scanned smile)
    values[30:, names.index("jaw")] = 0.3
    for k, v in enumerate(values):
        w.add(k, v)
    w.close()
    take = tmp_path / "phone.jsonl"
    assert main(["fit", str(tmp_path / "phone.arkit.csv"), "--out", str(take), "--age", "70"]) == 0
    chans, got = _take_values(take, face0)
    assert got[60, chans.index("zygomaticus_major_l")] == pytest.approx(0.385)
    assert got[60, chans.index("jaw")] == pytest.approx(0.3)
    assert got[60, chans.index("age")] == 70.0
    assert main(["replay", str(take), "--headless"]) == 0
    text = (tmp_path / "phone.arkit.csv").read_text()
    for kind, bad in damaged_texts(text).items():
        p = tmp_path / f"bad_{kind}.csv"
        p.write_text(bad, encoding="latin-1" if kind == "garbage" else "utf-8")
        _one_line_exit_2(capsys, ["fit", str(p), "--out", str(tmp_path / "o.jsonl")], tmp_path / "o.jsonl")


def test_a_take_rate_a_replay_refuses_is_one_line(tmp_path, face0, capsys) -> None:  # type: ignore[no-untyped-def]
    """--rate is a take's tick rate: 20000 wrote a take `puppet replay` refused (tick_rate above
    10000), 1e9 filled the memory with 2e9 ticks until the kernel killed the process; a long
    capture at a high rate that makes more values than a replay holds is refused before the fit."""
    from puppet.export.arkit import ArkitCsvWriter

    names = [c.name for c in face0.vocab.channels]
    phone = tmp_path / "phone.arkit.csv"
    w = ArkitCsvWriter(phone, names, 60.0)
    for k in range(30):
        w.add(k, np.array(face0.vocab.defaults()))
    w.close()
    out = tmp_path / "o.jsonl"
    for rate in ("20000", "1e9", "0.5", "nan"):
        assert "--rate" in _one_line_exit_2(capsys, ["fit", str(phone), "--rate", rate, "--out", str(out)], out)
    assert main(["fit", str(phone), "--rate", "10000", "--out", str(out)]) == 0
    assert main(["replay", str(out), "--out", str(tmp_path / "o.csv")]) == 0
    out.unlink()
    lines = phone.read_text().splitlines()
    lines.append("02:00:00:00.000" + lines[-1][len("00:00:00:29.000"):])  # the capture runs two hours
    phone.write_text("\n".join(lines) + "\n")
    assert "more than a take holds" in _one_line_exit_2(
        capsys, ["fit", str(phone), "--rate", "10000", "--out", str(out)], out)


def test_fit_weights_and_capture_rates_out_of_range_are_one_line(tmp_path, performance, capsys) -> None:  # type: ignore[no-untyped-def]
    """--smooth or --sparsity nan / inf was a ValueError traceback from the solver's factorisation,
    --smooth -1 a LinAlgError, --sparsity -5 a take with every channel at its maximum; --fps 1e-300
    spread a point cache's samples over 1e300 s."""
    times, names, pts = performance
    track = tmp_path / "track.csv"
    write_landmark_csv(track, times[:6], pts[:6], names)
    out = tmp_path / "o.jsonl"
    for option, value in (("--smooth", "nan"), ("--smooth", "inf"), ("--smooth", "-1"), ("--sparsity", "nan"),
                          ("--sparsity", "inf"), ("--sparsity", "-5")):
        err = _one_line_exit_2(capsys, ["fit", str(track), option, value, "--out", str(out)], out)
        assert option in err, err
    for value in ("1e-300", "1e300", "0.5"):
        err = _one_line_exit_2(capsys, ["fit", str(track), "--fps", value, "--out", str(out)], out)
        assert "--fps" in err, err
        assert main(["recognize", str(track), "--fps", value]) == 2
        assert "--fps" in capsys.readouterr().err
    assert main(["fit", str(track), "--smooth", "0", "--sparsity", "0", "--no-relinearise", "--out", str(out)]) == 0


def test_damaged_landmark_csvs_are_one_line_errors(tmp_path, performance, capsys) -> None:  # type: ignore[no-untyped-def]
    times, names, pts = performance
    good = tmp_path / "good.csv"
    write_landmark_csv(good, times[:6], pts[:6], names)
    text = good.read_text()
    variants = damaged_texts(text)
    variants["wrong_name"] = text.replace("nose_tip_", "nose_tipp_")
    variants["times_back"] = text.replace(f"\n{times[3]:.6f},", f"\n{times[1]:.6f},")
    variants["wrong_axis"] = text.replace("chin_y", "chin_q")
    variants["two_points"] = "time,chin_x,chin_y,chin_z,nose_tip_x,nose_tip_y,nose_tip_z\n0,1,2,3,4,5,6\n"
    for kind, bad in variants.items():
        p = tmp_path / f"bad_{kind}.csv"
        p.write_text(bad, encoding="latin-1" if kind == "garbage" else "utf-8")
        out = tmp_path / f"{kind}.jsonl"
        err = _one_line_exit_2(capsys, ["fit", str(p), "--out", str(out)], out)
        assert str(p) in err, (kind, err)
        _one_line_exit_2(capsys, ["recognize", str(p)], out)


def test_damaged_correspondence_files(tmp_path, performance, capsys) -> None:  # type: ignore[no-untyped-def]
    times, names, pts = performance
    good = tmp_path / "good.csv"
    write_landmark_csv(good, times[:4], pts[:4], names)
    cases = {"not_json": "{", "list": "[1, 2]", "unknown_rig_point": '{"points": {"a": "nose", "b": "chin"}}',
             "number": '{"points": {"a": 3}}', "twice": '{"points": {"a": "chin", "b": "chin", "c": "nose_tip", '
             '"d": "glabella"}}', "missing_input": '{"points": {"zz": "chin", "b": "nose_tip", "c": "glabella", '
             '"d": "subnasale"}}'}
    for kind, text in cases.items():
        corr = tmp_path / f"{kind}.json"
        corr.write_text(text)
        out = tmp_path / f"{kind}.jsonl"
        _one_line_exit_2(capsys, ["fit", str(good), "--map", str(corr), "--out", str(out)], out)


def test_bad_output_and_options_are_one_line_errors(tmp_path, performance, capsys) -> None:  # type: ignore[no-untyped-def]
    times, names, pts = performance
    good = tmp_path / "good.csv"
    write_landmark_csv(good, times[:4], pts[:4], names)
    _one_line_exit_2(capsys, ["fit", str(good), "--out", str(tmp_path / "x.mp4")], tmp_path / "x.mp4")
    _one_line_exit_2(capsys, ["fit", str(good), "--out", str(tmp_path / "no" / "x.jsonl")], tmp_path / "no")
    _one_line_exit_2(capsys, ["fit", str(good), "--neutral", "99", "--out", str(tmp_path / "n.jsonl")],
                     tmp_path / "n.jsonl")
    _one_line_exit_2(capsys, ["fit", str(tmp_path / "missing.csv"), "--out", str(tmp_path / "m.jsonl")],
                     tmp_path / "m.jsonl")


def test_a_damaged_cache_file_is_never_trusted(tmp_path, face0, basis0) -> None:  # type: ignore[no-untyped-def]
    from puppet.capture import cache

    settler, basis, tpl = basis0
    path = tmp_path / "c.npz"
    cache._save(path, basis, tpl)
    got = cache._load(path, face0.model)
    assert got is not None and np.array_equal(got[0].columns, basis.columns)
    path.write_bytes(path.read_bytes()[:5000])
    assert cache._load(path, face0.model) is None
    cols = basis.columns.copy()
    cols[0, 0, 0] = np.nan
    from dataclasses import replace

    cache._save(path, replace(basis, columns=cols), tpl)
    assert cache._load(path, face0.model) is None
    import sim.face

    assert cache._key(face0.model) != cache._key(sim.face.default_model(1))


def test_fit_on_a_rig_file_records_it_for_replay(tmp_path, performance, capsys) -> None:  # type: ignore[no-untyped-def]
    import sim.face
    from puppet.session import read_session

    times, names, pts = performance
    rig = tmp_path / "face.npz"
    sim.save_rig(sim.face.default_rig(0), rig)
    csv_path = tmp_path / "track.csv"
    write_landmark_csv(csv_path, times[:12], pts[:12], names)
    take = tmp_path / "rig.jsonl"
    assert main(["fit", str(csv_path), "--rig", str(rig), "--out", str(take), "--no-relinearise"]) == 0
    assert read_session(take).header["rig"]["path"] == str(rig.resolve())
    capsys.readouterr()
    assert main(["replay", str(take), "--headless"]) == 0


def test_the_arkit_reader_inverts_the_export_mapping(tmp_path, arkit_expressible) -> None:  # type: ignore[no-untyped-def]
    """Every channel the ARKit export writes one-to-one comes back with its value (5 decimals)."""
    from puppet.capture.arkit_in import read_arkit_csv
    from puppet.export.arkit import GAZE_LIDS, SIMPLE_SHAPES, ArkitCsvWriter
    from sim.channels import CHANNEL_NAMES, CHANNEL_SPECS

    one_to_one = {b + s for b in set(SIMPLE_SHAPES.values()) - {"orbicularis_oculi"} for s in ("_l", "_r")}
    one_to_one |= {"jaw", "mentalis", "orbicularis_oris_l", "orbicularis_oris_r", "eyes_yaw", "eyes_pitch"}  # the press: a half
    rng = np.random.default_rng(15)
    values = np.tile([s.default for s in CHANNEL_SPECS], (20, 1))
    for ch in one_to_one:
        j = CHANNEL_NAMES.index(ch)
        values[:, j] = rng.uniform(-1.0 if ch.startswith("eyes") else 0.0, 1.0, 20)
    # the eyes turned towards or away from each other, each eye within its range (yaw +- vergence)
    one_to_one.add("eyes_vergence")
    yaw = values[:, CHANNEL_NAMES.index("eyes_yaw")]
    values[:, CHANNEL_NAMES.index("eyes_vergence")] = rng.uniform(-1.0, 1.0, 20) * (1.0 - np.abs(yaw))
    # a shape calibrated to the scans writes its channels up to its span; a shape that shares another
    # channel (pressed lips lift the chin, ...) comes back whole when that channel is at least its share
    arkit_expressible(values, list(CHANNEL_NAMES))
    # the lids follow the gaze (GAZE_LIDS): a pose comes back whole when its lids are at least the gaze's share
    pitch = values[:, CHANNEL_NAMES.index("eyes_pitch")]
    for look, (lid, share) in GAZE_LIDS.items():
        gaze = np.maximum(pitch if look == "EyeLookUp" else -pitch, 0.0)
        for s in ("_l", "_r"):
            j = CHANNEL_NAMES.index(lid + s)
            values[:, j] = np.maximum(values[:, j], share * gaze)
    path = tmp_path / "rt.arkit.csv"
    w = ArkitCsvWriter(path, list(CHANNEL_NAMES), 60.0)
    for k, v in enumerate(values):
        w.add(k, v)
    w.close()
    cap = read_arkit_csv(path)
    assert np.allclose(cap.times, np.arange(20) / 60.0)
    for ch in sorted(one_to_one):
        j = CHANNEL_NAMES.index(ch)
        assert np.allclose(cap.values[:, j], values[:, j], atol=1e-5), ch


def test_the_commands_as_a_user_runs_them(tmp_path, face0, basis0) -> None:  # type: ignore[no-untyped-def]
    """Separate processes: a bad file is one line and exit 2; recognize --json prints the list."""
    import os
    import subprocess
    import sys

    from puppet.capture.take import write_take

    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[2])}
    bad = tmp_path / "bad.csv"
    bad.write_text("time,chin_x,chin_y\n0,1,2\n")
    out = tmp_path / "o.jsonl"
    p = subprocess.run([sys.executable, "-m", "puppet", "fit", str(bad), "--out", str(out)], env=env,
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == 2 and len(p.stderr.strip().splitlines()) == 1 and not out.exists(), p.stderr
    values = np.tile(np.array(face0.vocab.defaults()), (60, 1))
    take = tmp_path / "still.jsonl"
    write_take(take, face0, values, 60.0, {"test": True})
    p = subprocess.run([sys.executable, "-m", "puppet", "recognize", str(take), "--json"], env=env,
                       capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr
    spans = json.loads(p.stdout)
    from sim.facs import EXPRESSIONS

    assert [s["expression"] for s in spans] == ["neutral"]
    assert set(spans[0]["scores"]) == {*EXPRESSIONS, "neutral"}


def test_a_csv_field_beyond_the_csv_modules_limit_is_one_line(tmp_path, capsys) -> None:  # type: ignore[no-untyped-def]
    """A cell of 200,000 characters (a pasted blob, a file that lost its line ends) in a landmark
    CSV and in a Live Link CSV: one line naming the file, not the csv module's own exception."""
    blob = "[" * 200_000
    for name, text in {"points.csv": f"time,chin_x,chin_y,chin_z\n0,{blob},1,2\n",
                       "phone.csv": f"Timecode,BlendShapeCount,JawOpen\n00:00:00:00.000,1,{blob}\n"}.items():
        p = tmp_path / name
        p.write_text(text)
        err = _one_line_exit_2(capsys, ["fit", str(p), "--out", str(tmp_path / "o.jsonl")], tmp_path / "o.jsonl")
        assert name in err and "line 2" in err, err


def test_a_damaged_point_cache_is_one_line(tmp_path, capsys) -> None:  # type: ignore[no-untyped-def]
    """A PC2 cut inside a float (a copy that stopped), and headers with negative counts: one line
    naming the file, before anything is fitted."""
    import struct

    (tmp_path / "cut.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    head = struct.Struct("<12siiffi")
    body = np.zeros(2 * 3 * 3, "<f4").tobytes()
    cases = {"cut": head.pack(b"POINTCACHE2\0", 1, 3, 0.0, 1.0, 2) + body[:-2],
             "negative points": head.pack(b"POINTCACHE2\0", 1, -1, 0.0, 1.0, 0),
             "negative samples": head.pack(b"POINTCACHE2\0", 1, 3, 0.0, 1.0, -2) + body}
    for kind, data in cases.items():
        (tmp_path / "cut.pc2").write_bytes(data)
        err = _one_line_exit_2(capsys, ["fit", str(tmp_path / "cut.pc2"), "--out", str(tmp_path / "o.jsonl")],
                               tmp_path / "o.jsonl")
        assert "cut.pc2" in err, (kind, err)


def test_a_report_naming_the_capture_or_the_take_is_refused(tmp_path, performance, capsys):  # type: ignore[no-untyped-def]
    """`--report` is written last: naming the capture itself (or the take) replaced the user's
    capture with the report. Refused in one line before anything is fitted; both files kept."""
    times, names, pts = performance
    cap = tmp_path / "capture.csv"
    write_landmark_csv(cap, times[:6], pts[:6], names)
    before = cap.read_bytes()
    take = tmp_path / "take.jsonl"
    err = _one_line_exit_2(capsys, ["fit", str(cap), "--report", str(cap), "--out", str(take)], take)
    assert "--report" in err and "capture.csv" in err
    assert cap.read_bytes() == before
    take.write_bytes(b"the user's take\n")
    assert main(["fit", str(cap), "--report", str(tmp_path / "." / "take.jsonl"), "--out", str(take)]) == 2
    assert "--report" in capsys.readouterr().err
    assert take.read_bytes() == b"the user's take\n"


def test_a_deep_or_huge_correspondence_file_is_one_short_line(tmp_path, performance, capsys) -> None:  # type: ignore[no-untyped-def]
    """--map files nested thousands deep ended in a RecursionError; a pasted 20,000-character name
    or a 400-digit number was quoted whole into an error line of 20,000 characters."""
    times, names, pts = performance
    good = tmp_path / "good.csv"
    write_landmark_csv(good, times[:4], pts[:4], names)
    cases = {"deep": "[" * 5000 + "]" * 5000,
             "deep_value": '{"points": {"a": ' + "[" * 5000 + "]" * 5000 + "}}",
             "long_value": json.dumps({"points": {"a": "x" * 20000}}),
             "long_key": json.dumps({"points": {"k" * 20000: "chin"}}),
             "long_extra_key": json.dumps({"points": {"a": "chin"}, "q" * 20000: 1}),
             "big_number": '{"points": {"a": ' + "9" * 400 + "}}"}
    for kind, text in cases.items():
        corr = tmp_path / f"{kind}.json"
        corr.write_text(text)
        out = tmp_path / f"{kind}.jsonl"
        err = _one_line_exit_2(capsys, ["fit", str(good), "--map", str(corr), "--out", str(out)], out)
        assert corr.name in err and len(err) < 400, (kind, err[:300])


def test_a_report_of_a_capture_that_is_not_fitted_is_refused(tmp_path, capsys) -> None:  # type: ignore[no-untyped-def]
    """--report is the fit's per-frame residual. A Live Link Face CSV is converted through the ARKit
    map and a WAV analysed as a voice: neither is fitted, and --report was silently ignored (no
    report, nothing said). Refused in one line before the face loads; nothing written."""
    import wave

    phone = tmp_path / "phone.csv"
    phone.write_text("Timecode,BlendShapeCount,JawOpen\n00:00:00:00.000,1,0.0\n00:00:00:01.000,1,0.5\n")
    speech = tmp_path / "speech.wav"
    with wave.open(str(speech), "wb") as w:
        w.setnchannels(1)
        w.setsampwidth(2)
        w.setframerate(16000)
        w.writeframes(b"\x00\x00" * 1600)
    take, report = tmp_path / "take.jsonl", tmp_path / "report.csv"
    for capture, what in ((phone, "ARKit"), (speech, "voice")):
        err = _one_line_exit_2(capsys, ["fit", str(capture), "--report", str(report), "--out", str(take)], take)
        assert "--report" in err and capture.name in err and what in err, err
        assert not report.exists()
    # the fit's other options and a voice's missing ones were dropped the same way
    for capture, extra in ((phone, ["--smooth", "0.1"]), (phone, ["--neutral", "3"]), (phone, ["--map", "ibug68"]),
                           (speech, ["--age", "70"]), (speech, ["--no-relinearise"]), (speech, ["--fps", "30"]),
                           (phone, ["--voice-profile", str(speech)])):
        err = _one_line_exit_2(capsys, ["fit", str(capture), *extra, "--out", str(take)], take)
        assert extra[0] in err and capture.name in err, err


def test_an_input_of_unknown_type_names_every_type_fit_reads(tmp_path, capsys) -> None:  # type: ignore[no-untyped-def]
    """`puppet fit speech.mp3` was told to bring a .csv, .c3d or .pc2, leaving out the voice's .wav
    that fit reads too; the line names it now."""
    clip = tmp_path / "speech.mp3"
    clip.write_bytes(b"ID3\x03\x00" + bytes(64))
    assert main(["fit", str(clip), "--out", str(tmp_path / "t.jsonl")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "speech.mp3" in err and ".wav" in err and ".c3d" in err, err
    assert not (tmp_path / "t.jsonl").exists()
