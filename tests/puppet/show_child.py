"""A live show to kill: the real LiveCore recording on the wall clock at 60 Hz, a dial turned every
tick, and the number of the tick being started written to a shared file before each tick (so the
killer knows what the process had when it died). Used by the SIGKILL tests and
benchmarks/recording_loss.py.

    python tests/puppet/show_child.py RECORDING COUNTER_FILE [FSYNC_LOG]

With FSYNC_LOG, the writer's fsync log and each tick's start time are written there (JSON) when
the process gets SIGTERM."""

from __future__ import annotations

import json
import mmap
import signal
import struct
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from devices.events import ControlEvent  # noqa: E402
from puppet import live  # noqa: E402
from puppet.mapping import Mapper  # noqa: E402
from puppet.session import SessionWriter  # noqa: E402

SGI = "sgi:///dev/ttyCHILD"


def main() -> int:
    record, counter = sys.argv[1], sys.argv[2]
    log_path = sys.argv[3] if len(sys.argv) > 3 else None
    face = live.load_face()
    spec = live.build_mapping(face.vocab, None, [SGI])
    writer = SessionWriter(record, live.session_header(face, spec, 60.0, [SGI]))
    core = live.LiveCore(face, Mapper(spec, face.vocab), writer=writer)
    with open(counter, "r+b") as fh:
        shared = mmap.mmap(fh.fileno(), 8)
    starts: list[float] = []

    def started(c: live.LiveCore) -> None:
        starts.append(time.monotonic())
        struct.pack_into("q", shared, 0, c.tick_count)

    core.before_tick.append(started)
    n = [0]

    def drain() -> list:
        n[0] += 1
        return [ControlEvent(SGI, f"dial{n[0] % 8}", "dial", 0.01, None, 2, time.monotonic())]

    stop = live.StopFlag()
    stop.install()
    live.run_realtime(core, drain, None, stop=stop)
    writer.close(core.tick_count)
    if log_path:
        log = list(writer.syncer.log) if writer.syncer else []
        Path(log_path).write_text(json.dumps({"fsyncs": log, "tick_starts": starts}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
