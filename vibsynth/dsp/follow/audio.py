"""Audio mode: program audio -> loudness, brightness, onsets, and what the focus lets shake.

Loudness -> intensity
    ITU-R BS.1770 K-weighting (the loudness standard's pre-filter: a +4 dB shelf above 1.5 kHz
    and a 38 Hz high-pass), mean square over 10 ms, in dB (``-0.691 + 10 log10``: LUFS-like, a
    full-scale 1 kHz sine reads -3), then attack/release ballistics (5 ms / 10 ms by default; the
    attack acts on power, so a sound out of silence is there within a hop; the release in dB, a
    steady fade). The release is short by default because a fall is a step too: the live budget is
    half of any 20 dB level step within 15 ms end to end, and the tracker's part is 4 ms up and
    15 ms down at 10 ms (a 120 ms release, smoother for music, takes 79 ms down). Wide-band audio
    has many degrees of freedom in 10 ms, so the fast meter barely ripples (0.3 dB SD on noise).
    The tracker maps ``range_db`` of it onto the knob range.
Brightness -> balance
    The spectral tilt (dB per octave, least squares over octave bands 63 Hz - 8 kHz, each band's
    power smoothed over ``balance_ms``), the audio analogue of t1 on V1 (V1 is a tilt of the
    10-1000 Hz log spectrum). ``balance = (tilt - TILT_CENTRE_DB) / TILT_PER_UNIT_DB``: octave-band
    power of pink noise (music's long-term average) is flat, white noise rises 3 dB/octave; with
    -1 dB/octave at balance 0 and 2.5 dB/octave per unit, measured program spans the live range:
    noise low-passed at 500 Hz (rumble, explosions) -2.8, a male voice -0.2 .. +0.2, espeak +0.8,
    white noise +1.6, a bright chime +2.6 (docs/follow.md).
Onsets -> transients
    Rises of the power in five bands (< 150 Hz, 150-600 Hz, 600 Hz - 2.5 kHz, 2.5-6 kHz, > 6 kHz),
    each over the newest 5 ms against the 20 ms before, in dB, weighted over the bands (``all``:
    their mean) (:mod:`vibsynth.dsp.follow.onsets`). The detector runs on its own 2.5 ms grid
    whatever the frame period (live 2.7 ms, offline 5 ms: the same onsets); a frame reports the
    onsets of the grid steps that ended within it. An onset fires at a 5 dB rise (a hi-hat's
    25 dB in the top band alone reaches it; ``beat`` and ``bass``, which weigh the noisy low
    bands, at 10.8 and 17.3 dB so that steady noise does not fire), re-armed once the function
    falls below half that, at most once per 30 ms, unless 10 ms after an onset the sound is
    10 dB louder than it was in that onset's first 10 ms (a hit right after a faint pre-echo,
    or a file that starts mid-sound). The short reference is what finds each hit of a drum loop:
    the former 60 ms reference, with a 9 dB threshold over three bands, measured a hit 100-200 ms
    after a loud one over that one's decay and missed a third of them (docs/follow.md).
Focus
    ``all``: loudness as is. ``effects``: a *tonality* score lowers the drive by up to
    :data:`TONAL_PENALTY_DB`. Tonality is voice-band periodicity: the normalised autocorrelation
    peak at lags of 2.5-14 ms (70-400 Hz pitch) above 0.5, times the share of power in
    100 Hz - 4 kHz above 0.5 (a male voice's fundamental lies below 250 Hz), held through the
    unvoiced gaps of speech (20 ms attack, 400 ms release). Measured at 40 ms: voices 0.84-0.97,
    noise 0.37, a crumple 0.28, a camera shutter 0.22. Voices and sustained tones are held down;
    noisy impacts, explosions, engines' rumble and footsteps pass; transients are scaled by
    ``1 - tonality`` too. ``bass``: the level of the content below 150 Hz drives intensity,
    onsets of the low band only. ``beat``: intensity falls :data:`BEAT_DEPTH_DB` below the
    loudness except right after low-weighted onsets (100 ms decay): steady sound does not shake.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray
from scipy import signal

from vibsynth.dsp.follow.loudness import k_weighting_sos
from vibsynth.dsp.follow.onsets import OnsetDetector
from vibsynth.dsp.follow.params import TrackerParams
from vibsynth.dsp.follow.stream import BoxcarAtEnds, HopSums, SosStream

__all__ = [
    "AUDIO_RATE_HZ",
    "MIN_AUDIO_RATE_HZ",
    "AudioAnalyzer",
    "TILT_CENTRE_DB",
    "TILT_PER_UNIT_DB",
    "TONAL_PENALTY_DB",
    "BEAT_DEPTH_DB",
]

AUDIO_RATE_HZ = 16000.0
MIN_AUDIO_RATE_HZ = 8000.0
#: Spectral tilt (dB/octave) that maps to balance 0, and dB/octave per balance unit.
TILT_CENTRE_DB = -1.0
TILT_PER_UNIT_DB = 2.5
TONAL_PENALTY_DB = 30.0
BEAT_DEPTH_DB = 20.0
_LEVEL_WINDOW_S = 0.010
_SPECTRUM_WINDOW_S = 0.032
_PITCH_WINDOW_S = 0.040
_PITCH_LAGS_S = (1 / 400.0, 1 / 70.0)
_TONAL_ATTACK_S = 0.02
_TONAL_RELEASE_S = 0.4
_BEAT_DECAY_S = 0.1
_OCTAVES_HZ = (63.0, 125.0, 250.0, 500.0, 1000.0, 2000.0, 4000.0, 8000.0)
#: band edges of the onset detector (Hz) and each focus' weights of the bands' rises
_ONSET_EDGES_HZ = (150.0, 600.0, 2500.0, 6000.0)
_ONSET_WEIGHTS = {
    "all": (0.2, 0.2, 0.2, 0.2, 0.2),
    "effects": (0.2, 0.2, 0.2, 0.2, 0.2),
    "bass": (1.0, 0.0, 0.0, 0.0, 0.0),
    "beat": (0.6, 0.3, 0.1, 0.0, 0.0),
}
_ONSET_STEP_S = 0.0025
_ONSET_SHORT_S = 0.005
_ONSET_REFERENCE_S = 0.020
_ONSET_REFRACTORY_S = 0.030
_ONSET_THRESHOLD_DB = 5.0
_ONSET_RETRIGGER_DB = 10.0
_ONSET_RETRIGGER_S = 0.010
#: A band's rise over 5 ms that steady noise exceeds once in a thousand steps is about this over
#: sqrt(bandwidth x 5 ms) (measured on white noise: 12.6 dB below 150 Hz, 3.2 dB over 2.5-6 kHz);
#: a focus' threshold is at least _ONSET_NOISE_MARGIN times its weighted bands' (root sum of
#: squares), so the low bands that ``bass`` and ``beat`` weigh do not fire on noise.
_ONSET_NOISE_DB = 12.0
_ONSET_NOISE_MARGIN = 1.25


def _smoothing(tau_s: float, hop_s: float) -> float:
    return 1.0 - math.exp(-hop_s / tau_s)


class AudioAnalyzer:
    """Per-frame loudness, drive level, balance and onsets of program audio at the internal rate.

    Parameters
    ----------
    fs : float
        Internal rate (Hz, >= 8 kHz).
    hop : int
        Samples per frame.
    params : TrackerParams
    balance_limits : tuple of float
    """

    def __init__(self, *, fs: float, hop: int, params: TrackerParams, balance_limits: tuple[float, float]) -> None:
        self.fs = float(fs)
        self.hop = int(hop)
        self.hop_s = self.hop / self.fs
        self.balance_limits = balance_limits
        self.kfilter = SosStream(k_weighting_sos(fs))
        self.level_window = max(1, int(round(_LEVEL_WINDOW_S * fs)))
        self._level = BoxcarAtEnds(self.level_window)
        self.bass_filter = SosStream(np.asarray(signal.butter(4, 150.0, output="sos", fs=fs), dtype=np.float64))
        self._bass = BoxcarAtEnds(self.level_window)
        nyq = 0.5 * fs
        edges = _ONSET_EDGES_HZ
        self._onset_filters = [
            SosStream(np.asarray(signal.butter(2, edges[0], output="sos", fs=fs), dtype=np.float64)),
            *(
                SosStream(np.asarray(signal.butter(2, (lo, hi), btype="bandpass", output="sos", fs=fs)))
                for lo, hi in zip(edges[:-1], edges[1:])
            ),
            SosStream(np.asarray(signal.butter(2, min(edges[-1], 0.45 * fs), btype="high", output="sos", fs=fs))),
        ]
        self._onset_hops = HopSums(len(self._onset_filters))
        width = np.diff((0.0, *edges, 0.5 * fs))
        self._onset_noise = _ONSET_NOISE_DB / np.sqrt(width * _ONSET_SHORT_S)
        #: internal samples per step of the onset detector's grid
        self.onset_step = max(1, int(round(_ONSET_STEP_S * fs)))
        self._onset_fill = 0  # samples of the current step seen
        self._onset_pending = 0.0  # strength of an onset in a step after the last frame of a block
        # Spectrum for tilt and tonality: the last window of samples, one FFT per frame.
        self.n_fft = 1 << int(math.ceil(math.log2(_SPECTRUM_WINDOW_S * fs)))
        self.n_pitch = int(round(_PITCH_WINDOW_S * fs))
        self._history = np.zeros(max(self.n_fft, self.n_pitch))
        self._hann = np.hanning(self.n_fft)
        freqs = np.fft.rfftfreq(self.n_fft, 1.0 / fs)
        octaves = [f for f in _OCTAVES_HZ if f * math.sqrt(2.0) < nyq]
        self._octave_masks = np.array([(freqs >= f / math.sqrt(2)) & (freqs < f * math.sqrt(2)) for f in octaves])
        self._log2_f = np.log2(np.array(octaves))
        self._voice_mask = (freqs >= 100.0) & (freqs < 4000.0)
        self._all_mask = freqs >= 40.0
        win = np.hanning(self.n_pitch)
        self._pitch_win = win
        w_acf = np.fft.irfft(np.abs(np.fft.rfft(win, 2 * self.n_pitch)) ** 2)[: self.n_pitch]
        self._win_acf = w_acf / w_acf[0]
        lo, hi = (int(round(t * fs)) for t in _PITCH_LAGS_S)
        self._lags = slice(lo, min(hi + 1, self.n_pitch // 2))
        self._pitch_every = max(1, int(round(0.01 / self.hop_s)))
        self._frame = 0
        self._octave_zi = np.zeros((1, len(octaves)))
        self._tonal_raw = 0.0
        self._tonal = 0.0
        self._loud = -200.0
        self._balance = 0.0
        self._beat = 0.0
        self.set_params(params)
        #: filter delay in front of the level window (the K filter's, ~0.1 ms at 1 kHz: none counted)
        self.filter_delay_s = 0.0

    def set_params(self, params: TrackerParams) -> None:
        self.params = params
        self.attack = _smoothing(params.attack_ms * 1e-3, self.hop_s)
        self.release = _smoothing(params.release_ms * 1e-3, self.hop_s)
        self.balance_alpha = _smoothing(params.balance_ms * 1e-3, self.hop_s)
        self.onsets = getattr(self, "onsets", None) or OnsetDetector(
            self.onset_step / self.fs,
            _ONSET_WEIGHTS[params.focus],
            threshold_db=_ONSET_THRESHOLD_DB,
            short_s=_ONSET_SHORT_S,
            reference_s=_ONSET_REFERENCE_S,
            refractory_s=_ONSET_REFRACTORY_S,
            retrigger_db=_ONSET_RETRIGGER_DB,
            retrigger_s=_ONSET_RETRIGGER_S,
        )
        weights = np.asarray(_ONSET_WEIGHTS[params.focus], dtype=np.float64)
        self.onsets.weights = weights
        self.onsets.threshold_db = max(
            _ONSET_THRESHOLD_DB, _ONSET_NOISE_MARGIN * float(np.sqrt(np.sum((weights * self._onset_noise) ** 2)))
        )
        self.gate_power = 10.0 ** ((params.gate_db + 0.691) / 10.0)

    def reset(self) -> None:
        for f in (self.kfilter, self.bass_filter, *self._onset_filters):
            f.reset()
        self._level.reset()
        self._bass.reset()
        self._onset_hops.reset()
        self._onset_fill = 0
        self._onset_pending = 0.0
        self.onsets.reset()
        self._history[:] = 0.0
        self._frame = 0
        self._octave_zi[:] = 0.0
        self._tonal_raw = self._tonal = 0.0
        self._loud = -200.0
        self._balance = 0.0
        self._beat = 0.0

    @property
    def tonality(self) -> float:
        """The held tonality score 0..1 of the newest frame."""
        return self._tonal

    def _spectral(
        self, joined: NDArray[np.float64], stops: NDArray[np.intp]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Balance and held tonality of the frames whose windows end at ``stops`` in ``joined``.

        One batch of FFTs per block: the windows' octave powers (smoothed over ``balance_ms``, a
        linear recursion run by ``lfilter``), the tilt of each, and every ``_pitch_every``-th
        frame's periodicity; only the asymmetric tonality hold runs frame by frame.
        """
        n = stops.size
        if n == 0:  # (lfilter returns an undefined state for an empty input)
            return np.zeros(0), np.zeros(0)
        idx = stops[:, np.newaxis] - self.n_fft + np.arange(self.n_fft)
        spec = np.abs(np.fft.rfft(joined[idx] * self._hann, axis=1)) ** 2
        a = self.balance_alpha
        octave, zf = signal.lfilter([a], [1.0, a - 1.0], spec @ self._octave_masks.T, axis=0, zi=self._octave_zi)
        self._octave_zi = zf
        balance = self._tilts(octave)
        frames = self._frame + np.arange(n)
        pitch = np.flatnonzero(frames % self._pitch_every == 0)
        raw = np.full(n, np.nan)
        if pitch.size:
            pidx = stops[pitch, np.newaxis] - self.n_pitch + np.arange(self.n_pitch)
            p = np.abs(np.fft.rfft(joined[pidx] * self._pitch_win, 2 * self.n_pitch, axis=1)) ** 2
            acf = np.fft.irfft(p, axis=1)[:, : self.n_pitch]
            zero = np.maximum(acf[:, :1], 1e-30)
            r = acf[:, self._lags] / zero / self._win_acf[self._lags]
            h = np.where(acf[:, 0] > 1e-20, np.clip(r.max(axis=1), 0.0, 1.0), 0.0)
            sp = spec[pitch]
            total = sp[:, self._all_mask].sum(axis=1)
            voice = np.where(total > 0, sp[:, self._voice_mask].sum(axis=1) / np.maximum(total, 1e-300), 0.0)
            raw[pitch] = np.clip((h - 0.5) / 0.3, 0, 1) * np.clip((voice - 0.5) / 0.3, 0, 1)
        tonal = np.empty(n)
        up, down = _smoothing(_TONAL_ATTACK_S, self.hop_s), _smoothing(_TONAL_RELEASE_S, self.hop_s)
        for i in range(n):
            if raw[i] == raw[i]:  # not NaN: a frame with a new periodicity measure
                self._tonal_raw = float(raw[i])
            self._tonal += (up if self._tonal_raw > self._tonal else down) * (self._tonal_raw - self._tonal)
            tonal[i] = self._tonal
        self._frame += n
        return balance, tonal

    def _tilts(self, octave: NDArray[np.float64]) -> NDArray[np.float64]:
        """Balance of each row of smoothed octave powers (held where fewer than 3 bands have power)."""
        ok = octave > np.maximum(1e-30, octave.max(axis=1, keepdims=True) * 1e-9)
        w = ok.astype(np.float64)
        count = w.sum(axis=1)
        x = np.broadcast_to(self._log2_f, octave.shape)
        xm = (w * x).sum(axis=1, keepdims=True) / np.maximum(count[:, np.newaxis], 1.0)
        with np.errstate(divide="ignore"):
            y = np.where(ok, 10.0 * np.log10(np.maximum(octave, 1e-300)), 0.0)
        xc = w * (x - xm)
        denom = (xc * xc).sum(axis=1)
        slope = (xc * y).sum(axis=1) / np.where(denom > 0, denom, 1.0)  # least squares through the bands
        lo, hi = self.balance_limits
        balance = np.clip((slope - TILT_CENTRE_DB) / TILT_PER_UNIT_DB, lo, hi)
        out = np.empty(octave.shape[0])
        for i, (valid, value) in enumerate(zip(count >= 3, balance)):
            if valid:
                self._balance = float(value)
            out[i] = self._balance
        return out

    def _onset_strength(self, y: NDArray[np.float64], ends: NDArray[np.intp]) -> NDArray[np.float64]:
        """Raw onset strength per frame: the detector on its own grid, each onset given to the frame
        in which its step ended (a step ending after the block's last frame: the next frame)."""
        step = self.onset_step
        steps = np.arange(step - self._onset_fill, y.size + 1, step, dtype=np.intp)
        self._onset_fill = (self._onset_fill + y.size) % step
        bands = np.stack([f(y) for f in self._onset_filters])
        power = self._onset_hops(bands * bands, steps) / step
        _, fired = self.onsets(power, self.gate_power)
        strength = np.zeros(ends.size)
        hits = np.flatnonzero(fired > 0)
        frame = np.searchsorted(ends, steps[hits], side="left")
        if self._onset_pending > 0 and ends.size:
            strength[0] = self._onset_pending
            self._onset_pending = 0.0
        for f, s in zip(frame.tolist(), fired[hits].tolist()):
            if f < ends.size:
                strength[f] = max(strength[f], s)
            else:
                self._onset_pending = max(self._onset_pending, s)
        return strength

    def process(
        self, y: NDArray[np.float64], ends: NDArray[np.intp]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """Analyse one block.

        Returns
        -------
        level_db, balance, strength, drive_db : ndarray, shape (k,)
            Fast loudness, balance knob, raw onset strength, the level that drives intensity.
        """
        p = self.params
        k = self.kfilter(y)
        power = self._level((k * k)[np.newaxis, :], ends)[0]
        b = self.bass_filter(y)
        bass_power = self._bass((b * b)[np.newaxis, :], ends)[0]
        strength = self._onset_strength(y, ends)
        joined = np.concatenate((self._history, y))
        base = self._history.size
        self._history = joined[-self._history.size :]
        n = ends.size
        level = np.empty(n)
        drive = np.empty(n)
        with np.errstate(divide="ignore"):
            raw = -0.691 + 10.0 * np.log10(power)
            bass_db = -0.691 + 10.0 * np.log10(bass_power)
        beat_alpha = _smoothing(_BEAT_DECAY_S, self.hop_s)
        balance, tonal = self._spectral(joined, (base + ends).astype(np.intp))
        for i in range(n):
            target = max(float(raw[i]), -200.0)
            if target > self._loud:  # attack on power: out of silence the level is there in one hop
                now = 10.0 ** (self._loud / 10.0)
                self._loud = 10.0 * math.log10(now + self.attack * (10.0 ** (target / 10.0) - now))
            else:  # release in dB: a steady fade, as the hand expects
                self._loud += self.release * (target - self._loud)
            level[i] = self._loud if self._loud > -199.0 else -np.inf
            if strength[i] > 0:
                self._beat = max(self._beat, 1.0)
            else:
                self._beat -= beat_alpha * self._beat
            if p.focus == "effects":
                drive[i] = level[i] - TONAL_PENALTY_DB * tonal[i]
            elif p.focus == "bass":
                drive[i] = bass_db[i]
            elif p.focus == "beat":
                drive[i] = level[i] - BEAT_DEPTH_DB * (1.0 - self._beat)
            else:
                drive[i] = level[i]
        if p.focus == "effects":
            strength = strength * (1.0 - tonal)
        return level, balance, strength, drive
