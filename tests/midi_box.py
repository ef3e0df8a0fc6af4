"""An emulated USB-MIDI controller as its own process on the JACK server named by
JACK_DEFAULT_SERVER: ``python midi_box.py CLIENT PORT``.

It opens an output port CLIENT:PORT (what the box sends) and an input port CLIENT-in:PORT in
(what the host sends it: lights), prints ``ready``, then obeys stdin lines ``send HH HH ...`` and
``quit``; every message received is printed as ``got HH HH ...``. Exiting removes its ports, which
is what unplugging the box looks like to the host.
"""

from __future__ import annotations

import os
import sys
import threading

import rtmidi


def main() -> int:
    client, port = sys.argv[1], sys.argv[2]
    os.environ.setdefault("JACK_NO_START_SERVER", "1")
    out = rtmidi.MidiOut(rtmidi.API_UNIX_JACK, name=client)
    out.open_virtual_port(port)
    inp = rtmidi.MidiIn(rtmidi.API_UNIX_JACK, name=f"{client}-in")
    inp.ignore_types(sysex=False, timing=False, active_sense=False)
    lock = threading.Lock()

    def received(item: tuple[list[int], float], data: object = None) -> None:
        with lock:
            print("got " + " ".join(f"{b:02x}" for b in item[0]), flush=True)

    inp.set_callback(received)
    inp.open_virtual_port(f"{port} in")
    with lock:
        print("ready", flush=True)
    for line in sys.stdin:
        words = line.split()
        if not words:
            continue
        if words[0] == "send":
            out.send_message([int(x, 16) for x in words[1:]])
        elif words[0] == "quit":
            break
    inp.close_port()
    out.close_port()
    inp.delete()  # python-rtmidi keeps the JACK client until delete()
    out.delete()
    return 0


if __name__ == "__main__":
    sys.exit(main())
