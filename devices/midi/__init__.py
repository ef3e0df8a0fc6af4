"""MIDI controllers: ``midi://`` ports through python-rtmidi (ALSA sequencer or JACK) and
``rawmidi://`` byte streams (rawmidi nodes, DIN MIDI on a UART).

``tokenizer`` turns bytes into MIDI messages (shared by every byte-stream path), ``profile`` reads
the controller profiles in ``profiles/``, ``decoder`` turns messages into control events by a
profile, ``feedback`` sends lights and rings, ``port`` and ``raw`` are the two backends, and
``discover`` lists the ports that are plugged in. Importing this package imports no MIDI library.
"""
