"""Running a lab session on the actuator: the trial in progress, its sounds, and its answer.

The runner plays stimuli with the engine's buffer voices (``play_buffer``), on top of the
texture, which it mutes for the run (and restores after). Everything a trial plays is
scheduled sample-exactly with ``at_frame``:

* a pair: stimulus A at frame ``F``, stimulus B at ``F + len(A) + gap`` (both queued before
  ``F``, :data:`LEAD_S` ahead of now);
* one stimulus (intensity: the one being adjusted, at the slider's gain; the reference at
  gain 1; resynthesis: the original or a version).

Nothing plays between trials: every new sound, answer, pause or stop first silences what
plays (``stop_buffer``: a 5 ms fade) and cancels a sound still waiting for its start frame.
A voice cannot be taken back once queued, so a silent voice is queued at the same frame: it
replaces the waiting one before it renders a sample. It would replace any voice playing at
that frame too, so a new sound never starts before a cancelled one's frame has passed (in
the rare case of an answer or a replay during the first stimulus of a pair, the next sound
waits at most that stimulus and the gap).

The runner's public :meth:`LabRunner.state` never names a stimulus: it is what a participant
may see (phase, progress, what can be played), pushed to every page on each change.
"""

from __future__ import annotations

import logging
import math
import threading
from collections.abc import Callable, Mapping, Sequence
from datetime import datetime, timezone
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from vibsynth.errors import InputError, ParameterError
from vibsynth.research.lab.orders import Trial
from vibsynth.research.lab.protocol import VERSION_TAGS
from vibsynth.research.lab.records import MAX_PLAYS, Answer
from vibsynth.research.lab.session import Session
from vibsynth.research.lab.stimuli import resampled

__all__ = ["LEAD_S", "VoiceEngine", "LabRunner"]

log = logging.getLogger(__name__)

#: A trial's first sound starts this long after it is asked for: every voice of a pair is queued
#: in the engine before the first one starts (the engine's command hand-off takes under a block).
LEAD_S = 0.05
#: A silent voice that replaces a voice still waiting for its start frame (cancelling it).
_SILENCE = np.zeros(1, dtype=np.float32)


class VoiceEngine(Protocol):
    """What the runner needs of :class:`vibsynth.engine.engine.Engine`."""

    fs: float
    channels: int

    @property
    def frame_position(self) -> int: ...

    def play_buffer(
        self,
        samples: NDArray[np.floating[Any]],
        *,
        channels: tuple[int, ...] | list[int] | None = None,
        gain: float = 1.0,
        at_frame: int | None = None,
    ) -> int: ...

    def set_buffer_gain(
        self, gain: float, *, channels: tuple[int, ...] | list[int] | None = None, glide_s: float = 0.01
    ) -> None: ...

    def stop_buffer(self, *, channels: tuple[int, ...] | list[int] | None = None) -> None: ...


def _now() -> datetime:
    return datetime.now(timezone.utc)


class LabRunner:
    """Runs one session at a time on an engine's buffer voices (thread-safe).

    Parameters
    ----------
    engine : VoiceEngine
    controller : Controller
        Mutes the texture during a run (``set_mute``) and stops the run on panic.
    on_change : callable, optional
        ``on_change(state)`` after every change of :meth:`state` (the studio pushes it to pages).
    clock : callable
        Returns the current time (timezone-aware) for the CSV's timestamps.
    """

    def __init__(
        self,
        engine: VoiceEngine,
        controller: Any,
        *,
        on_change: Callable[[dict[str, Any]], None] | None = None,
        clock: Callable[[], datetime] = _now,
    ) -> None:
        self.engine = engine
        self.controller = controller
        self.on_change = on_change
        self.clock = clock
        self._lock = threading.RLock()
        self._session: Session | None = None
        self._sounds: dict[str, NDArray[np.float32]] = {}
        self._channels: tuple[int, ...] | None = None
        self._muted_before: dict[int, bool] = {}
        self._phase = "idle"  # idle | familiarisation | test | done
        self._paused = False
        self._error = ""
        self._done_folder = ""
        self._fam_index = 0
        self._trial: Trial | None = None
        self._shown_at: datetime | None = None
        self._plays = 0
        self._reference_plays = 0
        self._slot_plays: dict[str, int] = {}
        self._gain = 1.0
        self._pending: list[int] = []  # start frames of voices queued and not started yet
        self._blocked_until = 0  # a cancelled voice's frame + 1: no new sound may start before it
        self._playing_until = 0  # frame at which the last queued sound ends
        self._stimulus_playing = False  # the adjusted stimulus (not the reference) is what plays
        self._unsubscribe_panic = controller.on_panic(self._on_panic) if hasattr(controller, "on_panic") else None

    # ------------------------------------------------------------------ state
    @property
    def session(self) -> Session | None:
        """The session being run (None when idle)."""
        return self._session

    @property
    def running(self) -> bool:
        """A session is being run (not idle, not done)."""
        return self._phase in ("familiarisation", "test")

    def state(self) -> dict[str, Any]:
        """What the page shows: never a stimulus' name or parameters.

        Returns
        -------
        state : dict
            ``status`` (idle, running, paused, done), ``protocol``, ``phase``
            (familiarisation, test), ``progress`` ``[k, n]`` (data trials: the trial shown, of
            all; 0 during familiarisation), ``familiarisation`` ``[k, n]``, ``slots`` (5 in
            resynthesis), ``gain_range``, ``start`` (the answer control's starting value),
            ``playing_s`` (seconds until what plays ends), ``folder`` (once done), ``error``.
        """
        with self._lock:
            s = self._session
            status = "idle" if self._phase == "idle" else "done" if self._phase == "done" else "running"
            if status == "running" and self._paused:
                status = "paused"
            out: dict[str, Any] = {"status": status, "error": self._error}
            if s is None:
                if self._done_folder:
                    out.update({"status": "done", "folder": self._done_folder})
                return out
            params = s.parameters
            total = s.total
            k = s.done + 1 if self._phase == "test" else (total if self._phase == "done" else 0)
            out.update(
                {
                    "protocol": s.protocol,
                    "phase": "familiarisation" if self._phase == "familiarisation" else "test",
                    "progress": [min(k, total), total],
                    "familiarisation": [
                        self._fam_index + (1 if self._phase == "familiarisation" else 0),
                        len(s.plan.familiarisation),
                    ],
                    "slots": len(self._trial.slots) if self._trial is not None else 0,
                    "gain_range": [params.gain_min, params.gain_max],
                    "method": s.method,
                    "start": self._start_value(),
                    "participant": s.participant,
                    "playing_s": max(0.0, (self._playing_until - self.engine.frame_position) / self.engine.fs),
                }
            )
            if self._phase == "done":
                out["folder"] = str(s.folder)
            return out

    def _start_value(self) -> float:
        """Where the answer control starts: log10(start gain) for intensity, else 0.5 (no hint)."""
        if self._trial is not None and self._trial.start_gain is not None:
            return math.log10(self._trial.start_gain)
        return 0.5

    def _changed(self) -> None:
        if self.on_change is not None:
            try:
                self.on_change(self.state())
            except Exception:  # a page that cannot be told must not stop the run
                log.exception("lab: could not publish the runner's state")

    # ------------------------------------------------------------------ starting and stopping
    def start(self, session: Session, *, channels: Sequence[int] | None = None) -> dict[str, Any]:
        """Run ``session`` (opened for writing) from its next trial; shows and plays the first trial.

        Parameters
        ----------
        session : Session
            Its stimuli are resampled to the engine's rate here (a second of 48 kHz audio each).
        channels : sequence of int, optional
            0-based engine channels to play on; None = every channel.

        Raises
        ------
        InputError
            Another session is running, or the session is complete.
        """
        chans = self._check_channels(channels)
        with self._lock:
            if self.running:
                raise InputError("a session is already running: stop it first")
            if session.complete:
                raise InputError(f"{session.folder}: the session is complete ({session.total} trials)")
            sounds = {
                sid: resampled(s.samples, s.fs, self.engine.fs).astype(np.float32)
                for sid, s in session.stimuli().items()
            }
            self._close_session()
            self._session, self._sounds, self._channels = session, sounds, chans
            self._error, self._done_folder, self._paused = "", "", False
            self._mute_texture()
            # A resumed session whose data trials have begun skips the familiarisation block (not saved).
            self._fam_index = 0
            self._phase = "familiarisation" if session.done == 0 and session.plan.familiarisation else "test"
            self._show()
        self._changed()
        return self.state()

    def clear_done(self) -> None:
        """Forget the finished session (a new one is being set up: the page shows the set-up, not its end)."""
        with self._lock:
            if not self.running:
                self._done_folder = ""
                if self._phase == "done":
                    self._close_session()
                    self._phase = "idle"

    def stop(self) -> dict[str, Any]:
        """End the run now (the session stays resumable from its CSV); the texture is unmuted."""
        with self._lock:
            self._silence()
            self._close_session()
            self._phase, self._paused = "idle", False
        self._changed()
        return self.state()

    def close(self) -> None:
        """Stop and stop listening to panics (the service is stopping)."""
        self.stop()
        if self._unsubscribe_panic is not None:
            self._unsubscribe_panic()

    def _close_session(self) -> None:
        self._restore_texture()
        if self._session is not None:
            self._session.close()
        self._session, self._trial, self._sounds = None, None, {}

    def _on_panic(self) -> None:
        with self._lock:
            if not self.running:
                return
            self._pending.clear()  # panic dropped every queued command, voices included
            self._playing_until = 0
            self._paused = True
            self._error = "panic: the run is paused"
        self._changed()

    def _check_channels(self, channels: Sequence[int] | None) -> tuple[int, ...] | None:
        if channels is None:
            return None
        chans = tuple(sorted({int(c) for c in channels}))
        if not chans or any(not 0 <= c < self.engine.channels for c in chans):
            raise ParameterError(f"channels must be in 1..{self.engine.channels}")
        return chans

    def _channel_list(self) -> list[int]:
        return list(self._channels) if self._channels is not None else list(range(self.engine.channels))

    def _mute_texture(self) -> None:
        self._muted_before = {c: bool(self.controller.get("mute", c)) for c in self._channel_list()}
        self.controller.set_mute(True, channels=list(self._muted_before), source="lab")

    def _restore_texture(self) -> None:
        unmute = [c for c, was in self._muted_before.items() if not was]
        if unmute:
            self.controller.set_mute(False, channels=unmute, source="lab")
        self._muted_before = {}

    # ------------------------------------------------------------------ trials
    def _show(self) -> None:
        """With the lock held: make the current trial the one shown, and play it."""
        s = self._session
        assert s is not None
        if self._phase == "familiarisation":
            self._trial = s.plan.familiarisation[self._fam_index]
        else:
            self._trial = s.next_trial
        self._shown_at = self.clock()
        self._plays = self._reference_plays = 0
        self._slot_plays = {}
        self._gain = self._trial.start_gain if self._trial and self._trial.start_gain else 1.0
        if s.method != "adjustment" and self._phase == "test":
            self._gain = s.staircase_gain()  # the staircase sets the level from the answers so far
        if s.protocol == "resynthesis":
            self._play_reference()
        else:
            self._play_trial(None)

    def _advance(self) -> None:
        """With the lock held: the next trial, the test after the familiarisation block, or done."""
        s = self._session
        assert s is not None
        if self._phase == "familiarisation":
            self._fam_index += 1
            if self._fam_index >= len(s.plan.familiarisation):
                self._phase = "test"
        if self._phase == "test" and s.complete:
            self._phase = "done"
            self._trial = None
            self._done_folder = str(s.folder)
            self._restore_texture()
            s.close()
            return
        self._show()

    # ------------------------------------------------------------------ sounds
    def _silence(self) -> None:
        """Stop what plays (5 ms fade) and cancel what waits for its start frame."""
        now = self.engine.frame_position
        chans = self._channels
        for start in self._pending:
            if start > now:
                self.engine.play_buffer(_SILENCE, channels=chans, gain=0.0, at_frame=start)
                self._blocked_until = max(self._blocked_until, start + 1)
        self._pending = []
        if self._playing_until > now:
            self.engine.stop_buffer(channels=chans)
        self._playing_until = 0
        self._stimulus_playing = False

    def _queue(self, sounds: Sequence[tuple[NDArray[np.float32], float]], gap_s: float = 0.0) -> None:
        """Play sounds one after the other, ``gap_s`` apart, sample-exactly from :data:`LEAD_S` ahead."""
        self._silence()
        at = max(self.engine.frame_position + int(round(LEAD_S * self.engine.fs)), self._blocked_until)
        gap = int(round(gap_s * self.engine.fs))
        for k, (samples, gain) in enumerate(sounds):
            if k:
                at += gap
            self.engine.play_buffer(samples, channels=self._channels, gain=gain, at_frame=at)
            self._pending.append(at)
            at += samples.size
        self._playing_until = at

    def _play_trial(self, slot: int | None) -> None:
        s, t = self._session, self._trial
        assert s is not None and t is not None
        if s.protocol == "dissimilarity":
            a, b = t.stimuli
            self._queue([(self._sounds[a], 1.0), (self._sounds[b], 1.0)], gap_s=s.parameters.gap_s)
            self._plays = min(self._plays + 1, MAX_PLAYS)
        elif s.protocol == "intensity":
            self._queue([(self._sounds[t.stimuli[0]], self._gain)])
            self._stimulus_playing = True
            self._plays = min(self._plays + 1, MAX_PLAYS)
        else:
            if slot is None or not 1 <= slot <= len(t.slots):
                raise ParameterError(f"play which version? give a slot 1..{len(t.slots)}")
            version = t.slots[slot - 1]
            sid = t.stimuli[0] if version == "O" else f"{t.stimuli[0]}.{VERSION_TAGS[version]}"
            self._queue([(self._sounds[sid], 1.0)])
            self._slot_plays[version] = min(self._slot_plays.get(version, 0) + 1, MAX_PLAYS)

    def _play_reference(self) -> None:
        s, t = self._session, self._trial
        assert s is not None and t is not None
        if s.protocol == "intensity":
            reference = str(s.meta.get("reference"))
            self._queue([(self._sounds[reference], 1.0)])
        elif s.protocol == "resynthesis":
            self._queue([(self._sounds[t.stimuli[0]], 1.0)])
        else:
            raise ParameterError("the dissimilarity protocol has no reference")
        self._reference_plays = min(self._reference_plays + 1, MAX_PLAYS)

    def _require_trial(self) -> None:
        if not self.running or self._trial is None:
            raise InputError("no trial is shown: start or resume a session")
        if self._paused:
            raise InputError("the run is paused: resume it first")

    # ------------------------------------------------------------------ the participant's actions
    def play(self, *, slot: int | None = None, gain: float | None = None) -> dict[str, Any]:
        """Play the current trial again: the pair, the stimulus being adjusted (at ``gain``), or a slot's version.

        Raises
        ------
        InputError
            No trial shown, or paused.
        ParameterError
            A gain outside the range, a slot outside 1..5.
        """
        with self._lock:
            self._require_trial()
            if gain is not None:
                self._refuse_gain_in_staircase()
                self._gain = self._check_gain(gain)
            self._play_trial(slot)
        self._changed()
        return self.state()

    def play_reference(self) -> dict[str, Any]:
        """Play the reference: the equalisation reference (intensity) or the original (resynthesis)."""
        with self._lock:
            self._require_trial()
            self._play_reference()
        self._changed()
        return self.state()

    def set_gain(self, gain: float) -> None:
        """The intensity slider moved: the stimulus plays on at the new gain (a 10 ms glide)."""
        with self._lock:
            self._require_trial()
            self._refuse_gain_in_staircase()
            self._gain = self._check_gain(gain)
            if self._stimulus_playing and self._playing_until > self.engine.frame_position:
                self.engine.set_buffer_gain(self._gain, channels=self._channels, glide_s=0.01)

    def _refuse_gain_in_staircase(self) -> None:
        if self._session is not None and self._session.method != "adjustment":
            raise ParameterError("the staircase sets the level: answer stronger or weaker")

    def _check_gain(self, gain: float) -> float:
        assert self._session is not None
        p = self._session.parameters
        if isinstance(gain, bool) or not isinstance(gain, (int, float)) or not math.isfinite(gain):
            raise ParameterError(f"gain must be a number in [{p.gain_min:g}, {p.gain_max:g}], got {gain!r}")
        # the slider's log10 value comes back as a float a rounding away from the ends
        if not p.gain_min * (1 - 1e-9) <= gain <= p.gain_max * (1 + 1e-9):
            raise ParameterError(f"gain = {gain:g} is outside [{p.gain_min:g}, {p.gain_max:g}]")
        return min(max(float(gain), p.gain_min), p.gain_max)

    def answer(
        self, *, value: float | None = None, ratings: Mapping[int, float] | None = None, judgement: str | None = None
    ) -> dict[str, Any]:
        """Record the answer (data trials; familiarisation answers are not saved) and show the next trial.

        Parameters
        ----------
        value : float
            Intensity: the gain; dissimilarity: the rating 0..1.
        ratings : mapping of int to float
            Resynthesis: slot (1..5) -> rating 0..1.
        judgement : str
            An intensity staircase: ``stronger`` or ``weaker`` (the stimulus vs the reference).

        Raises
        ------
        ParameterError
            The answer is out of range (nothing is recorded; the trial stays).
        InputError
            No trial, paused, or the CSV cannot be written (the run stops: resume it).
        """
        with self._lock:
            self._require_trial()
            s, t = self._session, self._trial
            assert s is not None and t is not None
            answered_at = self.clock()
            if s.method != "adjustment":
                value = self._gain
            elif s.protocol == "intensity" and value is not None:
                value = self._check_gain(value)
            if s.protocol == "resynthesis":
                if ratings is None or sorted(ratings) != list(range(1, len(t.slots) + 1)):
                    raise ParameterError(f"rate every slot 1..{len(t.slots)}")
                by_version = {t.slots[k - 1]: v for k, v in ratings.items()}
                answer = Answer(
                    ratings=by_version, slot_plays=dict(self._slot_plays), reference_plays=self._reference_plays
                )
            else:
                answer = Answer(
                    value=value, plays=self._plays, reference_plays=self._reference_plays, judgement=judgement
                )
            if self._phase == "test":
                try:
                    s.record(answer, shown_at=self._shown_at or answered_at, answered_at=answered_at)
                except InputError as exc:
                    self._silence()
                    self._error = str(exc)
                    self._close_session()
                    self._phase = "idle"
                    self._changed()
                    raise
            else:
                from vibsynth.research.lab.records import make_row

                make_row(  # checked like a data answer, then dropped: familiarisation is not saved
                    s.protocol,
                    t,
                    answer,
                    params=s.params(),
                    shown_at=answered_at,
                    answered_at=answered_at,
                    participant=s.participant,
                    gain_range=(s.parameters.gain_min, s.parameters.gain_max),
                )
            self._silence()
            self._error = ""
            self._advance()
        self._changed()
        return self.state()

    def pause(self) -> dict[str, Any]:
        """Silence and hold the current trial (a participant's break)."""
        with self._lock:
            if not self.running:
                raise InputError("no session is running")
            self._silence()
            self._paused = True
        self._changed()
        return self.state()

    def resume(self) -> dict[str, Any]:
        """Continue after a pause: the current trial is shown again and plays."""
        with self._lock:
            if not self.running:
                raise InputError("no session is running")
            if self._paused:
                self._paused = False
                self._error = ""
                self._mute_texture_again()
                if self._session is not None and self._session.protocol == "resynthesis":
                    self._play_reference()
                else:
                    self._play_trial(None)
        self._changed()
        return self.state()

    def _mute_texture_again(self) -> None:
        chans = self._channel_list()
        self.controller.set_mute(True, channels=chans, source="lab")
