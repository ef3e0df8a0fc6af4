"""Damaged files through the real commands: how many variants of each format end in a traceback
(or a multi-line / huge error line, or a destroyed --out file) instead of a result or one short
line and exit 2. Same generators and seed as tests/files/.

    PYTHONPATH=$PWD .venv/bin/python benchmarks/damaged_files.py [FORMAT ...] [--show N]

Point PYTHONPATH at an older checkout to count what it did (the generators come from this one)."""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
import warnings
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "files"))

import formats  # noqa: E402


def _kind(text: str) -> str:
    """exc: a Python exception escaped the command; lost: it failed and destroyed the --out file;
    line: the error was several lines, thousands of characters or did not name the file."""
    if text.startswith("failed, and destroyed"):
        return "lost"
    if text.startswith(("error line", "exit 2:")):
        return "line"
    return "exc"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("formats", nargs="*", help="formats to run (default all)")
    ap.add_argument("--show", type=int, default=3, help="tracebacks to print per format")
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    chosen = [f for f in formats.FORMATS if not args.formats or f.name in args.formats]
    total = {"ok": 0, "error": 0, "traceback": 0}
    print(f"{'format':<12} {'variants':>8} {'ok':>6} {'error':>6} {'traceback':>9} {'(exc':>5} {'line':>5} "
          f"{'lost)':>5} {'s':>6}")
    with tempfile.TemporaryDirectory(prefix="damaged-") as tmp:
        for fmt in chosen:
            t0 = time.perf_counter()
            seen = formats.run_format(fmt, Path(tmp) / fmt.name)
            n = sum(len(v) for v in seen.values())
            kinds = [_kind(text) for _, text in seen["traceback"]]
            print(f"{fmt.name:<12} {n:>8} {len(seen['ok']):>6} {len(seen['error']):>6} "
                  f"{len(seen['traceback']):>9} {kinds.count('exc'):>5} {kinds.count('line'):>5} "
                  f"{kinds.count('lost'):>5} {time.perf_counter() - t0:>6.1f}", flush=True)
            for name, text in seen["traceback"][: args.show]:
                last = [ln for ln in text.strip().splitlines() if ln.strip()][-1:]
                print(f"    {name[:40]}: {(last[0] if last else '')[:160]}")
            for k in total:
                total[k] += len(seen[k])
    print(f"{'all':<12} {sum(total.values()):>8} {total['ok']:>6} {total['error']:>6} {total['traceback']:>9}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
