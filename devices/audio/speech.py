"""Speech for building the default profile, for tests and for the benchmark: espeak-ng's synthetic
voice (Debian's `espeak-ng`), read into numpy. Nothing here runs in a live show."""

from __future__ import annotations

import os
import shutil
import subprocess
import tempfile

import numpy as np

from devices.audio.wavfile import read_wav

#: espeak-ng phoneme input for each mouth class (en-us mnemonics), said slowly.
PHONEMES: dict[str, list[str]] = {
    "A": ["[[A:]]", "[[aa]]"],
    "I": ["[[i:]]"],
    "U": ["[[u:]]"],
    "E": ["[[E]]"],
    "O": ["[[o:]]"],
    "M": ["[[mmmm]]"],
    "F": ["[[ffff]]", "[[vvvv]]"],
}


def have_espeak() -> bool:
    return shutil.which("espeak-ng") is not None


def synthesize(text: str, voice: str = "en-us", speed: int = 120, pitch: int = 50,
               amplitude: int = 100) -> tuple[np.ndarray, int]:
    """(mono float samples, rate) of espeak-ng saying `text` (plain words or [[phonemes]])."""
    if not have_espeak():
        raise RuntimeError("espeak-ng is not installed (Debian package espeak-ng)")
    fd, path = tempfile.mkstemp(suffix=".wav")
    os.close(fd)
    try:
        subprocess.run(["espeak-ng", "-v", voice, "-s", str(speed), "-p", str(pitch), "-a", str(amplitude),
                        "-z", "-w", path, text], check=True, capture_output=True, timeout=60)
        return read_wav(path)
    finally:
        os.unlink(path)
