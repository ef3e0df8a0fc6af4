"""The voice analysis: sample blocks in, mouth controls out, with no device, thread or clock in it.

``VoiceAnalyzer.feed(block, t)`` takes mono float samples and the time of the block's first sample
(seconds on any clock) and returns one ``VoiceFrame`` per 10 ms hop that became complete. Each
frame holds the noise-gated loudness and the mouth shapes a map binds (jaw opening, lip rounding,
lip spread, lips closed for m/b/p, upper lip raise for f/v). The same samples always give the same
frames, bit for bit, whatever the block sizes: the live device and `puppet fit speech.wav` share it.

How (after uLipSync's MFCC templates and JALI's jaw/lip split; docs/audio.md):
  * level: RMS of the newest 25 ms window in dBFS; a gate opens above ``gate_db`` and closes below
    ``gate_db - GATE_HYSTERESIS_DB`` after ``hold`` seconds (soft speech between words keeps it open);
    loudness maps ``gate_db .. ceil_db`` linearly to 0..1 with attack/release smoothing.
  * shape: 12 MFCCs (pre-emphasis 0.97, Hamming, 26 mel bands 100 Hz .. 7.6 kHz, c1..c12) matched
    against the profile's templates (A, I, U, E, O, closed M, fricative F) by standardised distance;
    a softmax turns distances into weights, and each template's mouth shape is mixed by them.
  * jaw follows the loudness times the vowels' openness; the lip shapes follow the gate's presence,
    so a rounded "oo" stays rounded when it is said softly.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from devices.audio.profile import SHAPES, VoiceProfile

HOP_S = 0.010
WINDOW_S = 0.025
N_MELS = 26
N_CEPS = 12
MEL_LO_HZ = 100.0
MEL_HI_HZ = 7600.0
PRE_EMPHASIS = 0.97
GATE_HYSTERESIS_DB = 6.0
#: The controls a frame carries, in order (each 0..1).
CONTROLS = ("level", "jaw", "round", "spread", "closed", "upper_lip")


@dataclass(frozen=True, slots=True)
class VoiceFrame:
    """One analysis hop. t: time of the newest sample in the window (the caller's clock); db: the
    window's RMS level in dBFS; gate: whether the gate is open; vowel: the best template's name
    ("" when gated); values: CONTROLS in order, each 0..1."""

    t: float
    db: float
    gate: bool
    vowel: str
    values: tuple[float, ...]


@dataclass(frozen=True)
class AnalyzerSettings:
    """Tuning: gate and loudness range in dBFS, time constants in seconds."""

    gate_db: float = -45.0
    ceil_db: float = -12.0
    hold: float = 0.12
    attack: float = 0.015
    release: float = 0.08
    shape_attack: float = 0.02
    shape_release: float = 0.06
    temperature: float = 0.35


def mel_filterbank(rate: float, nfft: int, n_mels: int = N_MELS, lo: float = MEL_LO_HZ,
                   hi: float = MEL_HI_HZ) -> np.ndarray:
    """(n_mels, nfft//2+1) triangular filters on the mel scale (1127 ln(1 + f/700)), each of unit
    area, so a band's energy does not depend on its width or on the sample rate."""
    hi = min(hi, 0.47 * rate)
    mel = lambda f: 1127.0 * np.log1p(np.asarray(f, dtype=np.float64) / 700.0)  # noqa: E731
    inv = lambda m: 700.0 * np.expm1(np.asarray(m, dtype=np.float64) / 1127.0)  # noqa: E731
    edges = inv(np.linspace(mel(lo), mel(hi), n_mels + 2))
    freqs = np.arange(nfft // 2 + 1) * rate / nfft
    fb = np.zeros((n_mels, freqs.size))
    for m in range(n_mels):
        a, c, b = edges[m], edges[m + 1], edges[m + 2]
        up = (freqs - a) / (c - a)
        down = (b - freqs) / (b - c)
        tri = np.clip(np.minimum(up, down), 0.0, None)
        if tri.sum() == 0.0:  # a band narrower than one bin: take the nearest bin
            tri[int(np.argmin(np.abs(freqs - c)))] = 1.0
        fb[m] = tri / tri.sum()
    return fb


def dct_matrix(n_in: int, n_out: int) -> np.ndarray:
    """Orthonormal DCT-II rows 1..n_out (c0, the overall level, is left out)."""
    k = np.arange(1, n_out + 1)[:, None]
    n = np.arange(n_in)[None, :]
    return np.sqrt(2.0 / n_in) * np.cos(np.pi * k * (2 * n + 1) / (2 * n_in))


class FeatureExtractor:
    """MFCCs of one window at a given sample rate; buffers are made once."""

    def __init__(self, rate: float) -> None:
        self.rate = float(rate)
        self.win = max(16, int(round(WINDOW_S * rate)))
        self.nfft = 1 << (self.win - 1).bit_length()
        self.window = np.hamming(self.win)
        self.fb = mel_filterbank(rate, self.nfft)
        self.dct = dct_matrix(N_MELS, N_CEPS)

    def mfcc(self, frame: np.ndarray) -> np.ndarray:
        """12 cepstral coefficients of `frame` (win samples, float64)."""
        x = np.empty_like(frame)
        x[0] = frame[0]
        x[1:] = frame[1:] - PRE_EMPHASIS * frame[:-1]
        spec = np.fft.rfft(x * self.window, self.nfft)
        power = spec.real * spec.real + spec.imag * spec.imag
        bands = self.fb @ power
        return self.dct @ np.log(bands + 1e-10)


def _coef(dt: float, tau: float) -> float:
    """One-pole smoothing coefficient for a step of dt with time constant tau (0: no smoothing)."""
    return 1.0 if tau <= 0.0 else 1.0 - math.exp(-dt / tau)


class VoiceAnalyzer:
    """Samples -> VoiceFrames (see the module docstring). Not thread-safe: one feeder."""

    def __init__(self, rate: float, profile: VoiceProfile | None = None,
                 settings: AnalyzerSettings | None = None) -> None:
        if not (rate >= 8000.0 and math.isfinite(rate)):
            raise ValueError(f"sample rate {rate!r} Hz is too low for voice analysis (needs >= 8000)")
        self.rate = float(rate)
        self.profile = profile if profile is not None else VoiceProfile.default()
        self.settings = settings or AnalyzerSettings()
        self.features = FeatureExtractor(rate)
        self.hop = max(1, int(round(HOP_S * rate)))
        self._dt = self.hop / self.rate
        self._names = list(self.profile.templates)
        self._means = np.array([self.profile.templates[n] for n in self._names], dtype=np.float64)
        self._scale = np.asarray(self.profile.scale, dtype=np.float64)
        self._shapes = np.array([SHAPES[n] for n in self._names], dtype=np.float64)  # (K, 5)
        s = self.settings
        self._a_up, self._a_down = _coef(self._dt, s.attack), _coef(self._dt, s.release)
        self._s_up, self._s_down = _coef(self._dt, s.shape_attack), _coef(self._dt, s.shape_release)
        self.reset()

    def reset(self) -> None:
        """Forget the past (a new stream starts): buffers, gate, smoothed values."""
        self._buf = np.zeros(self.features.win, dtype=np.float64)
        self._since_hop = 0
        self._t_next: float | None = None
        self._gate = False
        self._below = 0.0
        self._level = 0.0
        self._presence = 0.0
        self._shape = np.zeros(5)

    @property
    def gate_open(self) -> bool:
        return self._gate

    def feed(self, block: np.ndarray, t: float) -> list[VoiceFrame]:
        """Analyse `block` (mono samples in -1..1, any length), whose first sample is at time `t`."""
        x = np.asarray(block, dtype=np.float64).reshape(-1)
        if x.size and not np.all(np.isfinite(x)):
            x = np.nan_to_num(x, nan=0.0, posinf=1.0, neginf=-1.0)
        x = np.clip(x, -1.0, 1.0)
        out: list[VoiceFrame] = []
        hop = self.hop
        i = 0
        while i < x.size:
            take = min(hop - self._since_hop, x.size - i)
            chunk = x[i:i + take]
            buf = self._buf  # take <= hop < win: shift left, append
            buf[:-take] = buf[take:]
            buf[-take:] = chunk
            self._since_hop += take
            i += take
            if self._since_hop == hop:
                self._since_hop = 0
                out.append(self._frame(t + (i - 1) / self.rate))
        return out

    def _frame(self, t: float) -> VoiceFrame:
        s = self.settings
        frame = self._buf
        rms = math.sqrt(float(np.dot(frame, frame)) / frame.size)
        db = 20.0 * math.log10(rms) if rms > 1e-10 else -200.0
        if db >= s.gate_db:
            self._gate = True
            self._below = 0.0
        elif self._gate and db < s.gate_db - GATE_HYSTERESIS_DB:
            self._below += self._dt
            if self._below >= s.hold:
                self._gate = False
        elif self._gate:
            self._below = 0.0
        vowel = ""
        if self._gate and db >= s.gate_db:
            loud = min(1.0, (db - s.gate_db) / (s.ceil_db - s.gate_db))
            weights = self._weights(self.features.mfcc(frame))
            target = weights @ self._shapes
            vowel = self._names[int(np.argmax(weights))]
            presence = 1.0
        elif self._gate:  # held open between sounds: the lips relax, nothing is classified
            loud, presence, target = 0.0, 1.0, np.zeros(5)
        else:
            loud, presence, target = 0.0, 0.0, np.zeros(5)
        self._level = _follow(self._level, loud, self._a_up, self._a_down)
        self._presence = _follow(self._presence, presence, self._a_up, self._a_down)
        for j in range(5):
            self._shape[j] = _follow(float(self._shape[j]), float(target[j]), self._s_up, self._s_down)
        jaw_open, rnd, spread, closed, upper = (float(v) for v in self._shape)
        openness = min(1.0, 0.35 + 0.65 * self._level)  # a soft vowel still opens the jaw a little
        values = (
            _clean(self._level),
            _clean(jaw_open * openness * self._presence),
            _clean(rnd * self._presence),
            _clean(spread * self._presence),
            _clean(closed * self._presence),
            _clean(upper * self._presence),
        )
        return VoiceFrame(t, db, self._gate, vowel, values)

    def _weights(self, mfcc: np.ndarray) -> np.ndarray:
        d = (mfcc[None, :] - self._means) / self._scale[None, :]
        dist2 = np.einsum("kc,kc->k", d, d) / d.shape[1]
        z = -(dist2 - dist2.min()) / self.settings.temperature
        w = np.exp(z)
        return w / w.sum()

    def classify(self, mfcc: np.ndarray) -> str:
        """The template nearest to one MFCC vector (for tests and `puppet learn`)."""
        return self._names[int(np.argmax(self._weights(mfcc)))]


#: Smallest change of a control that is sent as an event (values are 0..1).
STEP = 1.0 / 512


def changes(sent: list[float], values: tuple[float, ...]) -> list[int]:
    """Indices of the controls worth an event now (changed by STEP, or reaching exactly 0 or 1);
    `sent` is updated to what was sent. The live device and `puppet fit` send the same events."""
    out = []
    for i, v in enumerate(values):
        old = sent[i]
        if v != old and (abs(v - old) >= STEP or v == 0.0 or v == 1.0):
            sent[i] = v
            out.append(i)
    return out


def _follow(cur: float, target: float, up: float, down: float) -> float:
    """One attack/release step toward `target`; below 0.005 a release snaps to exactly 0 (a mouth at
    rest sends nothing more)."""
    nxt = cur + (target - cur) * (up if target > cur else down)
    return 0.0 if (target == 0.0 and nxt < 0.005) else nxt


def _clean(v: float) -> float:
    return 0.0 if v <= 0.0 else (1.0 if v >= 1.0 else v)


def frames_mfcc(samples: np.ndarray, rate: float, gate_db: float = -45.0) -> tuple[np.ndarray, np.ndarray]:
    """(mfccs (N, 12), dBFS (N,)) of every hop of a recording: what `puppet learn` and the profile
    builder average into templates."""
    fx = FeatureExtractor(rate)
    hop = max(1, int(round(HOP_S * rate)))
    x = np.clip(np.asarray(samples, dtype=np.float64).reshape(-1), -1.0, 1.0)
    feats, dbs = [], []
    for end in range(fx.win, x.size + 1, hop):
        frame = x[end - fx.win:end]
        rms = math.sqrt(float(np.dot(frame, frame)) / frame.size)
        db = 20.0 * math.log10(rms) if rms > 1e-10 else -200.0
        feats.append(fx.mfcc(frame))
        dbs.append(db)
    if not feats:
        return np.zeros((0, N_CEPS)), np.zeros(0)
    return np.array(feats), np.array(dbs)
