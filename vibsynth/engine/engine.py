"""The real-time engine: knobs with glide, bank crossfade, gain, mute, limiter.

``Engine.render(frames) -> float32 [frames, channels]`` works without any audio
device; outputs call :meth:`Engine.render_into` from their audio thread.

Per channel and per sample:

1. **Knobs** (intensity 0..1, balance, mute gain 0..1) follow *linear* ramps: a
   move to ``target`` with glide ``T`` reaches it exactly ``round(T * fs)`` samples
   later (0 = jump on that very sample). A new move mid-glide starts from the
   current value. Ramps are computed from integer sample counts, so the values do
   not depend on how the stream is cut into blocks.
2. **Gain** from the intensity knob ``k``: band level
   ``ceiling_db - range_db * (1 - k)`` (the bank is at 0 dB band level), i.e.
   ``exp(a k + b)``, times ``min(1, k / 0.01)`` so that ``k -> 0`` fades to true
   silence without a step (only knobs below 0.01 are affected).
3. **Crossfade**: balance -> fractional bank position ``p``; the sample is
   ``(1 - f) x_i[n] + f x_{i+1}[n]`` with ``i = floor(p)``, ``f = p - i``. All levels
   share one phase spectrum (see :mod:`vibsynth.engine.bank`), so this is a
   magnitude crossfade: no power dip, no grain change.
4. **Safety limiter**: the bank's per-level peaks are known, and ``|x| <=
   (1-f) peak_i + f peak_{i+1}``, so the gain is capped at
   ``limiter_ceiling / that bound``: the output can never exceed the ceiling, and
   the cap is a smooth function of the (smoothed) balance, so it never distorts or
   clicks (it acts like a gain reduction that tracks the balance knob). A final
   hard clip at the ceiling guards against float rounding and never engages in
   practice.
5. **Mute/panic**: mute is a third ramped gain (``mute_fade_s`` for a full fade);
   panic glides every intensity to 0 over the mute fade and drops scheduled commands.

Commands
--------
:meth:`submit` appends ``(seq, command)`` to a :class:`collections.deque` (atomic
in CPython, no lock a control thread can hold). At the start of each block the
audio thread drains it: immediate commands apply at the block's first sample;
commands with ``at_frame`` inside this or a later block are kept in a sorted list
and applied at **exactly** that sample (the block is split there); a command
whose ``at_frame`` has already passed applies at the block's first sample and is
counted in ``stats.late_commands``. ``applied_seq`` is the highest sequence number
the audio thread has taken (applied, or placed on its timeline if scheduled).

Real-time safety
----------------
Every per-sample array is preallocated for ``max_block`` frames; in steady state
(no new commands) :meth:`render_into` runs only ufuncs with ``out=`` and
allocates no arrays (checked with tracemalloc in the tests). Requests larger than
``max_block`` are rendered in pieces.
"""
from __future__ import annotations

import bisect
import itertools
import math
import time
from collections import deque
from dataclasses import dataclass
from typing import Sequence

import numpy as np
from numpy.typing import NDArray

from vibsynth.engine.bank import NoiseBank
from vibsynth.engine.commands import Command, Panic, SetGlide, SetKnob, SetMute
from vibsynth.errors import ParameterError

__all__ = ["Engine", "EngineStats", "KNOB_FADE_IN"]

#: Intensity knobs below this also fade linearly to silence (no step at 0).
KNOB_FADE_IN = 0.01

_INTENSITY, _BALANCE, _MUTE = 0, 1, 2


@dataclass
class EngineStats:
    """Counters the engine and its output update (plain attributes, read from any thread).

    Attributes
    ----------
    blocks : int
        Render calls.
    underflows : int
        Set by the output backend (from its driver's status flags).
    late_commands : int
        Scheduled commands whose frame had already passed when they arrived.
    load_last, load_peak, load_avg : float
        Render time as a fraction of the block period (last, peak since
        :meth:`take_peak`, exponential average).
    output_errors : int
        Device errors the output recovered from.
    """

    blocks: int = 0
    underflows: int = 0
    late_commands: int = 0
    load_last: float = 0.0
    load_peak: float = 0.0
    load_avg: float = 0.0
    output_errors: int = 0

    def take_peak(self) -> float:
        """Peak load since the last call (and reset it)."""
        peak, self.load_peak = self.load_peak, 0.0
        return peak


class _Ramps:
    """Linear ramps of one knob for every channel (state arrays shaped (C, 1))."""

    def __init__(self, channels: int, value: float) -> None:
        self.start = np.full((channels, 1), float(value))
        self.delta = np.zeros((channels, 1))
        self.pos = np.ones((channels, 1))
        self.length = np.ones((channels, 1))
        self.end_frame = 0  # absolute frame at which every ramp has finished

    def value(self, c: int) -> float:
        length = float(self.length[c, 0])
        return float(self.start[c, 0] + self.delta[c, 0] * (min(float(self.pos[c, 0]), length) / length))

    def target(self, c: int) -> float:
        return float(self.start[c, 0] + self.delta[c, 0])

    def move(self, c: int, target: float, samples: int, frame: int) -> None:
        current = self.value(c)
        self.start[c, 0] = current
        self.delta[c, 0] = float(target) - current
        if samples <= 0:
            self.pos[c, 0] = 1.0
            self.length[c, 0] = 1.0
        else:
            self.pos[c, 0] = 0.0
            self.length[c, 0] = float(samples)
            self.end_frame = max(self.end_frame, frame + samples)

    def fill(self, out: NDArray[np.float64], steps: NDArray[np.float64]) -> None:
        """Values after each of ``steps`` (1..m) samples, into ``out`` (C, m); no allocation."""
        np.add(self.pos, steps, out=out)
        np.minimum(out, self.length, out=out)
        np.divide(out, self.length, out=out)
        np.multiply(out, self.delta, out=out)
        np.add(out, self.start, out=out)

    def advance(self, m: int) -> None:
        np.add(self.pos, float(m), out=self.pos)
        np.minimum(self.pos, self.length, out=self.pos)


class Engine:
    """Multi-channel texture renderer over a :class:`~vibsynth.engine.bank.NoiseBank`.

    Parameters
    ----------
    bank : NoiseBank
    channels : int
        Output channels (each with its own knobs and read offset).
    ceiling_db, range_db : float
        Intensity mapping: knob 1 -> ``ceiling_db`` band level, (0, 1] spans ``range_db``.
    glide_s : float
        Initial glide of every channel (0 = jump).
    mute_fade_s : float
        Duration of a full mute/unmute/panic fade.
    limiter_ceiling : float
        No output sample exceeds this in absolute value (0 < ceiling <= 1).
    initial_intensity, initial_balance : float
    max_block : int
        Largest block rendered in one piece (buffers are sized for it).

    Attributes
    ----------
    fs : float
    channels : int
    stats : EngineStats
    """

    def __init__(
        self,
        bank: NoiseBank,
        *,
        channels: int = 1,
        ceiling_db: float = -40.0,
        range_db: float = 40.0,
        glide_s: float = 0.02,
        mute_fade_s: float = 0.01,
        limiter_ceiling: float = 0.891,
        initial_intensity: float = 0.0,
        initial_balance: float = 0.0,
        max_block: int = 4096,
    ) -> None:
        if int(channels) != channels or channels < 1 or channels > 64:
            raise ParameterError(f"channels must be an integer in 1..64, got {channels!r}")
        for name, value in (("ceiling_db", ceiling_db), ("range_db", range_db), ("glide_s", glide_s),
                            ("mute_fade_s", mute_fade_s), ("limiter_ceiling", limiter_ceiling)):
            if not math.isfinite(value):
                raise ParameterError(f"{name} must be finite, got {value!r}")
        if range_db <= 0:
            raise ParameterError(f"range_db must be > 0, got {range_db}")
        if glide_s < 0 or mute_fade_s < 0:
            raise ParameterError("glide and mute fade must be >= 0")
        if not 0 < limiter_ceiling <= 1:
            raise ParameterError(f"limiter_ceiling must be in (0, 1], got {limiter_ceiling}")
        if not 0.0 <= initial_intensity <= 1.0:
            raise ParameterError(f"initial intensity must be in [0, 1], got {initial_intensity}")
        if max_block < 1 or max_block >= bank.n_samples:
            raise ParameterError(f"max_block must be in 1..{bank.n_samples - 1}, got {max_block}")
        self.bank = bank
        self.fs = float(bank.fs)
        self.channels = int(channels)
        self.ceiling_db = float(ceiling_db)
        self.range_db = float(range_db)
        self.limiter_ceiling = float(limiter_ceiling)
        self.mute_fade_s = float(mute_fade_s)
        self.max_block = int(max_block)
        self.stats = EngineStats()

        self._queue: deque[tuple[int, Command]] = deque()
        self._seq = itertools.count(1)
        self._applied_seq = 0
        self._frame = 0
        self._scheduled: list[tuple[int, int, Command]] = []  # (at_frame, seq, command), sorted
        self._glide_s = [float(glide_s)] * self.channels
        self._muted = [False] * self.channels

        ch, mb = self.channels, self.max_block
        balance0 = float(np.clip(initial_balance, bank.balances[0], bank.balances[-1]))
        self._ramps = (_Ramps(ch, initial_intensity), _Ramps(ch, balance0), _Ramps(ch, 1.0))
        # Constants of the mappings.
        ln10_20 = math.log(10.0) / 20.0
        self._gain_a = self.range_db * ln10_20
        self._gain_b = (self.ceiling_db - self.range_db) * ln10_20
        lo, hi = float(bank.balances[0]), float(bank.balances[-1])
        self._pos_scale = (bank.levels - 1) / (hi - lo)
        self._pos_offset = -lo * self._pos_scale
        self._pos_max = float(bank.levels - 1)
        self._idx_max = bank.levels - 2
        self._n = bank.n_samples
        self._flat = bank.signals.reshape(-1)
        self._peaks = np.ascontiguousarray(bank.peaks, dtype=np.float64)
        self._dpeaks = np.append(np.diff(self._peaks), 0.0)
        # Preallocated buffers: per-sample (C, max_block) and static (C, 1) controls.
        self._steps = np.arange(1, mb + 1, dtype=np.float64)
        self._steps_int = np.arange(mb, dtype=np.int64)

        # Flat storage; _view() cuts C-contiguous (C, m) views (mixed dtypes or strided
        # operands would make numpy allocate temporary buffers).
        self._dyn = self._buffers(mb)
        self._static = self._buffers(1)
        self._static_exp = self._buffers(mb)
        self._static_valid = False
        self._static_m = -1
        self._read_exp = np.zeros(ch * mb, dtype=np.int64)
        self._read_exp[:ch] = bank.channel_offsets(ch) % self._n
        self._read_m = 1
        self._ceil32 = np.float32(self.limiter_ceiling)
        self._floor32 = np.float32(-self.limiter_ceiling)
        self._work = {
            "flat": np.zeros(ch * mb, dtype=np.int64),
            "lo": np.zeros(ch * mb, dtype=np.float32), "hi": np.zeros(ch * mb, dtype=np.float32),
        }

    def _buffers(self, width: int) -> dict[str, NDArray]:
        n = self.channels * width
        return {
            "k": np.zeros(n), "b": np.zeros(n), "m": np.zeros(n), "g": np.zeros(n), "t": np.zeros(n),
            "f": np.zeros(n), "i": np.zeros(n, dtype=np.int64),
            "G": np.zeros(n, dtype=np.float32), "F": np.zeros(n, dtype=np.float32),
        }

    def _view(self, flat: NDArray, m: int) -> NDArray:
        return flat[: self.channels * m].reshape(self.channels, m)

    # ------------------------------------------------------------------ control side
    def submit(self, command: Command) -> int:
        """Hand a command to the audio thread (any thread; never blocks). Returns its sequence number."""
        if not isinstance(command, (SetKnob, SetGlide, SetMute, Panic)):
            raise ParameterError(f"not an engine command: {command!r}")
        seq = next(self._seq)
        self._queue.append((seq, command))
        return seq

    @property
    def applied_seq(self) -> int:
        """Highest sequence number the audio thread has taken (applied or scheduled)."""
        return self._applied_seq

    @property
    def frame_position(self) -> int:
        """Frames rendered since the engine started (the stream clock of ``at_frame``)."""
        return self._frame

    def knob_values(self) -> list[tuple[float, float, bool]]:
        """Current (intensity, balance, muted) per channel, for status display (approximate while gliding)."""
        ki, kb, _ = self._ramps
        return [(ki.value(c), kb.value(c), self._muted[c]) for c in range(self.channels)]

    # ------------------------------------------------------------------ commands (audio thread)
    def _chans(self, channels: Sequence[int] | None) -> Sequence[int]:
        if channels is None:
            return range(self.channels)
        return [c for c in channels if 0 <= c < self.channels]

    def _apply(self, command: Command, frame: int) -> None:
        self._static_valid = False
        fs = self.fs
        if isinstance(command, SetKnob):
            ramps = self._ramps[_INTENSITY if command.name == "intensity" else _BALANCE]
            value = float(command.value)
            if command.name == "balance":
                value = min(max(value, float(self.bank.balances[0])), float(self.bank.balances[-1]))
            for c in self._chans(command.channels):
                glide = self._glide_s[c] if command.glide_s is None else float(command.glide_s)
                ramps.move(c, value, int(round(glide * fs)), frame)
        elif isinstance(command, SetGlide):
            for c in self._chans(command.channels):
                self._glide_s[c] = float(command.seconds)
        elif isinstance(command, SetMute):
            mute = self._ramps[_MUTE]
            target = 0.0 if command.muted else 1.0
            for c in self._chans(command.channels):
                self._muted[c] = bool(command.muted)
                distance = abs(target - mute.value(c))
                mute.move(c, target, int(round(self.mute_fade_s * fs * distance)), frame)
        elif isinstance(command, Panic):
            self._scheduled.clear()
            intensity = self._ramps[_INTENSITY]
            for c in range(self.channels):
                intensity.move(c, 0.0, int(round(self.mute_fade_s * fs)), frame)

    def _drain(self, block_start: int) -> None:
        queue = self._queue
        while queue:
            seq, command = queue.popleft()
            at = command.at_frame
            if at is None or at <= block_start:
                if at is not None and at < block_start:
                    self.stats.late_commands += 1
                self._apply(command, block_start)
            else:
                bisect.insort(self._scheduled, (at, seq, command), key=lambda item: (item[0], item[1]))
            if seq > self._applied_seq:
                self._applied_seq = seq

    # ------------------------------------------------------------------ rendering
    def _controls(self, buf: dict[str, NDArray], width: int, steps: NDArray[np.float64]) -> None:
        """Knob trajectories -> effective gain ``g``, level index ``i`` and fraction ``f`` (C, width)."""
        ki, kb, km = self._ramps
        k, b, m, g, t, f, i = (self._view(buf[n], width) for n in ("k", "b", "m", "g", "t", "f", "i"))
        ki.fill(k, steps)
        kb.fill(b, steps)
        km.fill(m, steps)
        # gain = exp(a k + b) * min(1, k / KNOB_FADE_IN)
        np.multiply(k, self._gain_a, out=g)
        np.add(g, self._gain_b, out=g)
        np.exp(g, out=g)
        np.multiply(k, 1.0 / KNOB_FADE_IN, out=t)
        np.minimum(t, 1.0, out=t)
        np.multiply(g, t, out=g)
        # balance -> fractional level position
        np.multiply(b, self._pos_scale, out=t)
        np.add(t, self._pos_offset, out=t)
        np.clip(t, 0.0, self._pos_max, out=t)
        np.floor(t, out=f)
        np.minimum(f, self._idx_max, out=f)
        np.copyto(i, f, casting="unsafe")
        np.subtract(t, f, out=f)
        # limiter: cap the gain at ceiling / peak bound of the crossfade
        self._dpeaks.take(i, out=t, mode="clip")
        np.multiply(t, f, out=t)
        np.add(t, self._peaks.take(i, out=b, mode="clip"), out=t)
        np.divide(self.limiter_ceiling, t, out=t)
        np.minimum(g, t, out=g)
        np.multiply(g, m, out=g)
        np.copyto(self._view(buf["G"], width), g, casting="same_kind")
        np.copyto(self._view(buf["F"], width), f, casting="same_kind")
        np.multiply(i, self._n, out=i)  # level index -> offset of its row in the flat bank

    def _read_view(self, m: int) -> NDArray[np.int64]:
        """Read indices ``(read_c + j) mod n`` as a contiguous (C, m) array (rebuilt only when m changes)."""
        if m != self._read_m:
            current = self._view(self._read_exp, self._read_m)[:, 0].copy()
            self._read_m = m
            view = self._view(self._read_exp, m)
            np.copyto(view, (current[:, np.newaxis] + np.arange(m)) % self._n)
        return self._view(self._read_exp, m)

    def _static_view(self, m: int) -> tuple[NDArray, NDArray, NDArray]:
        """Constant controls expanded to contiguous (C, m) arrays (recomputed after commands or when m changes)."""
        exp = self._static_exp
        if not self._static_valid:
            self._controls(self._static, 1, self._steps[:1])
            self._static_valid = True
            self._static_m = -1
        if m != self._static_m:
            for name in ("G", "F", "i"):
                np.copyto(self._view(exp[name], m), self._view(self._static[name], 1))
            self._static_m = m
        return self._view(exp["G"], m), self._view(exp["F"], m), self._view(exp["i"], m)

    def _segment(self, out: NDArray[np.float32], s0: int, s1: int, frame: int) -> None:
        """Render frames ``s0:s1`` of ``out`` (stream frame ``frame`` at ``s0``).

        In steady state (no knob ramping) every operand is a same-shape contiguous
        array, so numpy needs no iterator buffers: nothing is allocated.
        """
        m = s1 - s0
        ramping = frame < max(self._ramps[0].end_frame, self._ramps[1].end_frame, self._ramps[2].end_frame)
        if ramping:
            buf = self._dyn
            self._controls(buf, m, self._steps[:m])
            g, f, i_n = (self._view(buf[n], m) for n in ("G", "F", "i"))
        else:
            g, f, i_n = self._static_view(m)
        work = self._work
        idx = self._read_view(m)
        flat, lo, hi = (self._view(work[n], m) for n in ("flat", "lo", "hi"))
        np.add(i_n, idx, out=flat)
        self._flat.take(flat, out=lo, mode="clip")
        np.add(flat, self._n, out=flat)
        self._flat.take(flat, out=hi, mode="clip")
        np.subtract(hi, lo, out=hi)
        np.multiply(hi, f, out=hi)
        np.add(lo, hi, out=hi)
        np.multiply(hi, g, out=hi)
        np.minimum(hi, self._ceil32, out=hi)
        np.maximum(hi, self._floor32, out=hi)
        np.copyto(out[s0:s1], hi.T)
        # advance clocks
        np.add(idx, m, out=idx)
        np.remainder(idx, self._n, out=idx)
        if ramping:
            for r in self._ramps:
                r.advance(m)

    def _render_block(self, out: NDArray[np.float32]) -> None:
        frames = out.shape[0]
        start = self._frame
        self._drain(start)
        end = start + frames
        s = 0
        scheduled = self._scheduled
        while scheduled and scheduled[0][0] < end:
            at = scheduled[0][0]
            split = at - start
            if split > s:
                self._segment(out, s, split, start + s)
                s = split
            while scheduled and scheduled[0][0] == at:
                self._apply(scheduled.pop(0)[2], at)
        if s < frames:
            self._segment(out, s, frames, start + s)
        self._frame = end

    def render_into(self, out: NDArray[np.float32]) -> None:
        """Fill ``out`` (shape (frames, channels), float32, writable) with the next frames.

        Allocates nothing in steady state; safe to call from an audio callback.
        """
        t0 = time.perf_counter()
        frames = out.shape[0]
        done = 0
        while done < frames:
            step = min(self.max_block, frames - done)
            self._render_block(out[done : done + step])
            done += step
        stats = self.stats
        stats.blocks += 1
        if frames:
            load = (time.perf_counter() - t0) * self.fs / frames
            stats.load_last = load
            if load > stats.load_peak:
                stats.load_peak = load
            stats.load_avg += 0.01 * (load - stats.load_avg)

    def render(self, frames: int) -> NDArray[np.float32]:
        """Render the next ``frames`` frames into a new array.

        Returns
        -------
        out : ndarray, shape (frames, channels), float32
        """
        if int(frames) != frames or frames < 0:
            raise ParameterError(f"frames must be a non-negative integer, got {frames!r}")
        out = np.empty((int(frames), self.channels), dtype=np.float32)
        self.render_into(out)
        return out
