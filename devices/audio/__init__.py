"""A microphone as a control box: ``audio://NAME`` (devices.audio.device) and the voice analysis it
runs on its own thread (devices.audio.analysis), with voice profiles as data files."""
