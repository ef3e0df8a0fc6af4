"""A voice in its own process, for tests and the benchmark: a JACK client (JACK-Client) with one
output port that plays WAV files on command, the way a microphone is another program's port.

stdin:  ``play PATH`` (queued after what is playing), ``quit`` (the client goes: an unplug).
stdout: ``ready``, then per file ``start FRAME MONO OFFSET PERIOD`` (the JACK frame of its first sample,
the monotonic time its cycle began, its place in that cycle's block, the block's length) and ``done``.
Samples are resampled to the server's rate; nothing is played between files (digital silence)."""

from __future__ import annotations

import queue
import sys
import threading
import time

import jack
import numpy as np
from scipy.signal import resample_poly

from devices.audio.wavfile import read_wav


def main() -> int:
    name = sys.argv[1]
    client = jack.Client(name, no_start_server=True)
    port = client.outports.register("out_1")
    todo: queue.SimpleQueue[np.ndarray] = queue.SimpleQueue()
    notes: queue.SimpleQueue[str] = queue.SimpleQueue()
    state = {"cur": None, "pos": 0}

    @client.set_process_callback
    def process(frames: int) -> None:
        now = time.monotonic()  # this cycle's block is handed over now
        out = port.get_array()
        out[:] = 0.0
        filled = 0
        while filled < frames:
            cur = state["cur"]
            if cur is None:
                try:
                    cur = state["cur"] = todo.get_nowait()
                    state["pos"] = 0
                    notes.put(f"start {client.last_frame_time + filled} {now:.6f} {filled} {frames}")
                except queue.Empty:
                    return
            pos = state["pos"]
            n = min(frames - filled, len(cur) - pos)
            out[filled:filled + n] = cur[pos:pos + n]
            filled += n
            state["pos"] = pos + n
            if state["pos"] >= len(cur):
                state["cur"] = None
                notes.put("done")

    def report() -> None:
        while True:
            print(notes.get(), flush=True)

    threading.Thread(target=report, daemon=True).start()
    client.activate()
    print("ready", flush=True)
    rate = client.samplerate
    for line in sys.stdin:
        cmd, _, arg = line.strip().partition(" ")
        if cmd == "play":
            x, r = read_wav(arg)
            if r != rate:
                from math import gcd

                g = gcd(int(rate), int(r))
                x = resample_poly(x, int(rate) // g, int(r) // g)
            todo.put(np.asarray(x, dtype=np.float32))
        elif cmd == "quit":
            break
    client.deactivate()
    client.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
