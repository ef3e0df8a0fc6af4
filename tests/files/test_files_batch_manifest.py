"""A batch's manifests (`OUT/.puppet-batch/NAME.json`, which say an output is up to date) damaged
hundreds of ways: each damaged manifest only makes the batch redo that output, never a traceback."""

from __future__ import annotations

import json
from pathlib import Path

import damage
from puppet.batch.plan import Input, Output, up_to_date, write_outputs


def _written(tmp_path: Path) -> tuple[Output, Path, bytes]:
    item = Input(tmp_path / "take.jsonl", digest="d" * 64)
    o = Output(item, "export", "take.csv", "k" * 64, {})
    write_outputs(tmp_path, o, {"take.csv": b"tick,jaw\n0,0.5\n"})
    manifest = next((tmp_path / ".puppet-batch").glob("*.json"))
    assert up_to_date(tmp_path, o)
    return o, manifest, manifest.read_bytes()


def test_damaged_manifests_make_the_output_redone_never_a_traceback(tmp_path: Path) -> None:
    o, manifest, good = _written(tmp_path)
    n = current = 0
    for name, data in damage.json_variants(good, n=200):
        manifest.write_bytes(data)
        current += up_to_date(tmp_path, o)  # raises nothing, whatever the file holds
        n += 1
    assert n >= 150
    assert current <= n // 4, f"{current} of {n} damaged manifests still said up to date"


def test_a_manifest_nested_thousands_deep_through_the_batch_command(tmp_path: Path) -> None:
    """Through `puppet batch export`: the output is written again, exit 0 (it was a RecursionError)."""
    import formats

    formats.good_recording(tmp_path)
    out = tmp_path / "out"
    argv = ["batch", "export", str(tmp_path / "good.jsonl"), "--to", "csv", "--workers", "1", "--out", str(out)]
    assert formats.run_cli(argv, tmp_path / "good.jsonl").kind == "ok"
    manifest = next((out / ".puppet-batch").glob("*.json"))
    good = json.loads(manifest.read_text())
    manifest.write_text("[" * 5000 + "]" * 5000)
    r = formats.run_cli(argv, manifest)
    assert r.kind == "ok", r.text
    assert json.loads(manifest.read_text())["files"].keys() == good["files"].keys()
