"""The one entry point every control source uses: validate, remember, hand to the engine, notify.

OSC, MIDI, preset hot reload and the command line all go through a
:class:`Controller`, so a value is validated once, with one set of rules:

* NaN or infinite numbers are rejected (:class:`~vibsynth.errors.ParameterError`).
* intensity must lie in [0, 1]; balance within the configured live limits
  (default [-3.5, 3.5]); glide within [0, ``glide_max_s``]. Values outside are
  rejected with a message naming the range; nothing changes.
* channel numbers are 0-based here (adapters translate from their own convention).

Layers: a channel's knobs are driven by one control layer at a time, the highest active
one of ``knobs`` (direct control: OSC, MIDI, presets, the studio) < ``follow`` (the live
follower, control/follow) < ``sources`` (the spatial mixer) < ``clip`` (the clip player).
Direct knob moves on a channel a higher layer drives are remembered and play when that
layer releases the channel (:meth:`Controller.release`);
the engine enforces the same rule in stream order (see :mod:`vibsynth.engine.engine`), so
moves from the OSC fast path, which bypass this class, obey it too.

The controller keeps the *target* state for queries and pushes every change to
subscribers (e.g. OSC ``/notify`` clients): per channel and setting, the value the engine
will hold once every command submitted so far has taken effect. Each value remembers the
stream frame it takes effect at (now for immediate commands), and a command only replaces
a value that takes effect no later than it does, so timetagged bundles that arrive out of
time order still leave the latest-timed value as the target. Its lock guards only this
small state (and keeps submission order equal to state order); the audio thread never
takes it.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Protocol

from vibsynth.control.tap import InputTap
from vibsynth.engine.commands import (
    KNOB_NAMES,
    LAYER_NAMES,
    CancelLayer,
    Command,
    Panic,
    SetGlide,
    SetKnob,
    SetLayer,
    SetMute,
)
from vibsynth.errors import ParameterError, PresetError
from vibsynth.settings.models import bounds_of, default_of

if TYPE_CHECKING:
    from vibsynth.settings.models_config import Knobs

__all__ = [
    "EngineLike",
    "PresetLike",
    "KnobLimits",
    "ChannelState",
    "KnobEvent",
    "Controller",
]


class EngineLike(Protocol):
    """What the controller needs of an engine (see :class:`vibsynth.engine.engine.Engine`)."""

    channels: int
    fs: float

    def submit(self, command: Command) -> int: ...

    @property
    def applied_seq(self) -> int: ...

    @property
    def frame_position(self) -> int: ...


class PresetLike(Protocol):
    """What the controller needs of a preset (see :mod:`vibsynth.settings.presets`)."""

    @property
    def name(self) -> str: ...

    @property
    def intensity(self) -> float: ...

    @property
    def balance(self) -> float: ...

    @property
    def glide_ms(self) -> float | None: ...


@dataclass(frozen=True)
class KnobLimits:
    """Ranges accepted from live controls.

    Attributes
    ----------
    balance_min, balance_max : float
        Live balance range (knob units).
    glide_max_s : float
        Longest glide accepted.
    """

    balance_min: float = default_of("knobs.balance_min")
    balance_max: float = default_of("knobs.balance_max")
    glide_max_s: float = float(bounds_of("knobs.glide_ms")[1] or 0.0) / 1000.0


@dataclass(frozen=True)
class ChannelState:
    """Target state of one output channel."""

    intensity: float = 0.0
    balance: float = 0.0
    glide_s: float = 0.02
    muted: bool = False
    preset: str | None = None


@dataclass(frozen=True)
class KnobEvent:
    """A change pushed to subscribers: ``name`` in intensity, balance, glide, mute, preset, driver.

    intensity and balance are what the channel plays (its driving layer's targets); driver
    is the name of that layer (see :data:`~vibsynth.engine.commands.LAYER_NAMES`).
    """

    channel: int
    name: str
    value: KnobValue
    source: str


Listener = Callable[[KnobEvent], None]
PanicListener = Callable[[], None]

_KNOB_FIELDS = frozenset(KNOB_NAMES)

#: What a knob event carries: a number (intensity, balance, glide), a flag (mute) or a preset name.
KnobValue = float | str | bool | None

#: ChannelState field -> the name subscribers see (the same names as :meth:`Controller.get`).
_EVENT_NAMES = {"muted": "mute", "glide_s": "glide"}


def check_finite(name: str, value: float) -> float:
    """Reject NaN/inf and non-numbers; return the value as float."""
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise ParameterError(f"{name} must be a number, got {value!r}") from None
    if not math.isfinite(number):
        raise ParameterError(f"{name} must be a finite number, got {value!r}")
    return number


def check_range(name: str, value: float, low: float, high: float) -> float:
    """Reject a value outside [low, high] with a message naming the range."""
    number = check_finite(name, value)
    if not (low <= number <= high):
        raise ParameterError(f"{name} {number:g} is outside the allowed range [{low:g}, {high:g}]")
    return number


def _notify(listeners: Sequence[Listener], events: Sequence[KnobEvent]) -> None:
    """Call every listener with every event (outside the controller's lock)."""
    for listener in listeners:
        for event in events:
            listener(event)


class Controller:
    """Validated, thread-safe control of an engine.

    Parameters
    ----------
    engine : EngineLike
    limits : KnobLimits
    preset_resolver : callable, optional
        ``name -> PresetLike``; raises :class:`~vibsynth.errors.PresetError` for unknown names.
    initial_glide_s : float
        Glide every channel starts with.
    """

    def __init__(
        self,
        engine: EngineLike,
        *,
        limits: KnobLimits = KnobLimits(),
        preset_resolver: Callable[[str], PresetLike] | None = None,
        initial_glide_s: float = 0.02,
    ) -> None:
        self.engine = engine
        self.limits = limits
        self.preset_resolver = preset_resolver
        self._lock = threading.Lock()
        self._state = [ChannelState(glide_s=initial_glide_s) for _ in range(engine.channels)]
        # Stream frame at which each (channel, field) value takes effect.
        self._effective: list[dict[str, int]] = [{} for _ in range(engine.channels)]
        self._listeners: list[Listener] = []
        self._panic_listeners: list[PanicListener] = []
        # Direct-control (layer 0) targets, and the targets of the higher layers active per channel.
        self._knobs: list[dict[str, float]] = [{"intensity": 0.0, "balance": 0.0} for _ in range(engine.channels)]
        self._layers: list[dict[int, dict[str, float]]] = [{} for _ in range(engine.channels)]
        self._top = [0] * engine.channels
        self._last_seq = 0
        self.started_at = time.monotonic()
        self.error_counts: dict[str, int] = {}
        self.tap = InputTap()  # what the adapters receive, for monitors and status (control/tap.py)

    @classmethod
    def for_knobs(
        cls, engine: EngineLike, knobs: Knobs, *, preset_resolver: Callable[[str], PresetLike] | None = None
    ) -> Controller:
        """A controller with the typed ``knobs:`` section's live balance range and glide."""
        return cls(
            engine,
            limits=KnobLimits(balance_min=knobs.balance_min, balance_max=knobs.balance_max),
            preset_resolver=preset_resolver,
            initial_glide_s=knobs.glide_ms / 1000.0,
        )

    # ------------------------------------------------------------------ helpers
    @property
    def channels(self) -> int:
        return self.engine.channels

    def _channel_list(self, channels: Iterable[int] | None) -> tuple[int, ...]:
        if channels is None:
            return tuple(range(self.channels))
        out = tuple(sorted(set(int(c) for c in channels)))
        for c in out:
            if not (0 <= c < self.channels):
                raise ParameterError(f"channel {c + 1} does not exist (channels are 1..{self.channels})")
        if not out:
            raise ParameterError("no channel selected")
        return out

    def _engine_channels(self, chans: tuple[int, ...]) -> tuple[int, ...] | None:
        return None if len(chans) == self.channels else chans

    def _apply(self, command: Command, chans: tuple[int, ...], field: str, value: KnobValue, source: str) -> None:
        """Submit ``command`` and record ``field = value`` on ``chans`` where it is the latest-timed value.

        Both happen under the lock, so two threads setting the same knob leave the state
        equal to what the engine received last.
        """
        events: list[KnobEvent] = []
        with self._lock:
            seq = self.engine.submit(command)
            self._last_seq = max(self._last_seq, seq)
            at = command.at_frame
            frame = self.engine.frame_position if at is None else int(at)
            for c in chans:
                self._set_if_latest(c, field, value, frame, source, events)
            listeners = list(self._listeners) if events else []
        _notify(listeners, events)

    def _set_if_latest(
        self, c: int, field: str, value: KnobValue, frame: int, source: str, events: list[KnobEvent]
    ) -> None:
        """With the lock held: set ``field`` of channel ``c`` unless a later-timed value waits."""
        effective = self._effective[c]
        if frame < effective.get(field, -1):
            return
        effective[field] = frame
        if field in _KNOB_FIELDS:
            self._knobs[c][field] = float(value)  # type: ignore[arg-type]  # knob values are numbers
            if self._top[c] != 0:
                return  # remembered: plays when the higher layers release the channel
        self._state[c] = replace(self._state[c], **{field: value})  # type: ignore[arg-type]  # field names a ChannelState field
        events.append(KnobEvent(c, _EVENT_NAMES.get(field, field), value, source))

    def record(self, updates: Iterable[tuple[str, int, float]], seq: int, *, source: str) -> None:
        """Record knob moves another producer already handed to the engine (the OSC fast path).

        Parameters
        ----------
        updates : iterable of (knob name, 0-based channel, value)
            Validated values, applied immediately (not timetagged).
        seq : int
            The engine sequence number of the last of them (for :meth:`sync`).
        """
        events: list[KnobEvent] = []
        with self._lock:
            self._last_seq = max(self._last_seq, int(seq))
            frame = self.engine.frame_position
            for name, c, value in updates:
                self._set_if_latest(c, name, value, frame, source, events)
            listeners = list(self._listeners) if events else []
        _notify(listeners, events)

    def _update(self, chans: tuple[int, ...], field: str, value: KnobValue, source: str) -> None:
        """Record a state change that is not an engine command (e.g. the preset name)."""
        events: list[KnobEvent] = []
        with self._lock:
            for c in chans:
                self._state[c] = replace(self._state[c], **{field: value})  # type: ignore[arg-type]
                events.append(KnobEvent(c, _EVENT_NAMES.get(field, field), value, source))
            listeners = list(self._listeners)
        _notify(listeners, events)

    def count_error(self, kind: str) -> None:
        """Count a rejected input (adapters call this; shown in status)."""
        with self._lock:
            self.error_counts[kind] = self.error_counts.get(kind, 0) + 1

    # ------------------------------------------------------------------ knobs
    def validate_knob(self, name: str, value: float) -> float:
        """Check a knob value against its range; return it as float."""
        if name == "intensity":
            return check_range("intensity", value, 0.0, 1.0)
        if name == "balance":
            return check_range("balance", value, self.limits.balance_min, self.limits.balance_max)
        raise ParameterError(f"unknown knob {name!r}; knobs are {', '.join(KNOB_NAMES)}")

    def set_knob(
        self,
        name: str,
        value: float,
        *,
        channels: Sequence[int] | None = None,
        at_frame: int | None = None,
        glide_s: float | None = None,
        source: str = "api",
    ) -> float:
        """Move a knob (intensity 0..1 or balance) on channels, now or at a stream frame.

        Returns
        -------
        value : float
            The value applied.
        """
        number = self.validate_knob(name, value)
        if glide_s is not None:
            glide_s = check_range("glide", glide_s, 0.0, self.limits.glide_max_s)
        chans = self._channel_list(channels)
        command = SetKnob(name, number, self._engine_channels(chans), at_frame, glide_s)  # type: ignore[arg-type]
        self._apply(command, chans, name, number, source)
        return number

    def set_texture(
        self,
        intensity: float,
        balance: float,
        *,
        channels: Sequence[int] | None = None,
        at_frame: int | None = None,
        source: str = "api",
    ) -> None:
        """Set both knobs at once (both are validated before either changes)."""
        self.validate_knob("intensity", intensity)
        self.validate_knob("balance", balance)
        self.set_knob("balance", balance, channels=channels, at_frame=at_frame, source=source)
        self.set_knob("intensity", intensity, channels=channels, at_frame=at_frame, source=source)

    def set_glide(
        self, seconds: float, *, channels: Sequence[int] | None = None, at_frame: int | None = None, source: str = "api"
    ) -> float:
        """Set the glide time in seconds (0 = jump)."""
        number = check_range("glide", seconds, 0.0, self.limits.glide_max_s)
        chans = self._channel_list(channels)
        self._apply(SetGlide(number, self._engine_channels(chans), at_frame), chans, "glide_s", number, source)
        return number

    def set_mute(
        self, muted: bool, *, channels: Sequence[int] | None = None, at_frame: int | None = None, source: str = "api"
    ) -> None:
        """Mute (short fade out) or unmute channels; knob targets are kept."""
        chans = self._channel_list(channels)
        self._apply(SetMute(bool(muted), self._engine_channels(chans), at_frame), chans, "muted", bool(muted), source)

    def panic(self, *, source: str = "api") -> None:
        """Silence every channel now: intensity targets to 0, scheduled commands dropped, every
        channel handed back to direct knob control (clips stop, sources turn off: the panic
        listeners are told)."""
        events: list[KnobEvent] = []
        with self._lock:  # panic drops every scheduled command: nothing later-timed is waiting
            for effective in self._effective:
                effective.clear()
            for c in range(self.channels):
                self._layers[c].clear()
                if self._top[c] != 0:
                    self._top[c] = 0
                    self._show_top(c, source, events)
            listeners = list(self._listeners) if events else []
            panic_listeners = list(self._panic_listeners)
        _notify(listeners, events)
        self._apply(Panic(), tuple(range(self.channels)), "intensity", 0.0, source)
        for callback in panic_listeners:
            callback()

    def on_panic(self, callback: PanicListener) -> Callable[[], None]:
        """Call ``callback()`` after every panic (drivers drop their state); returns an unsubscribe function."""
        with self._lock:
            self._panic_listeners.append(callback)

        def unsubscribe() -> None:
            with self._lock:
                if callback in self._panic_listeners:
                    self._panic_listeners.remove(callback)

        return unsubscribe

    # ------------------------------------------------------------------ layers
    @staticmethod
    def layer_index(layer: str) -> int:
        """Engine index of a driving layer name (``follow``, ``sources`` or ``clip``; ``knobs`` is 0)."""
        try:
            return LAYER_NAMES.index(layer)
        except ValueError:
            raise ParameterError(f"unknown layer {layer!r}; layers are {', '.join(LAYER_NAMES)}") from None

    def _driving_index(self, layer: str) -> int:
        index = self.layer_index(layer)
        if index == 0:
            raise ParameterError("direct knob control is the base layer: use set_knob, not drive/release")
        return index

    def _show_top(self, c: int, source: str, events: list[KnobEvent]) -> None:
        """With the lock held: make ``_state[c]`` show the targets of the channel's top layer."""
        top = self._top[c]
        values = self._knobs[c] if top == 0 else self._layers[c][top]
        state = self._state[c]
        for name in KNOB_NAMES:
            if getattr(state, name) != values[name]:
                state = replace(state, **{name: values[name]})  # type: ignore[arg-type]
                events.append(KnobEvent(c, name, values[name], source))
        self._state[c] = state
        events.append(KnobEvent(c, "driver", LAYER_NAMES[top], source))

    def drive(
        self,
        layer: str,
        *,
        channels: Sequence[int] | None = None,
        intensity: float | None = None,
        balance: float | None = None,
        at_frame: int | None = None,
        glide_s: float | None = None,
        source: str = "api",
    ) -> None:
        """Move a driving layer's knob targets on channels (activating the layer there).

        Where ``layer`` becomes the highest active layer it takes the channel over (from
        ``at_frame``, in stream order); where a higher layer drives, the targets are kept
        for when it releases. A knob left None keeps the layer's target (on activation:
        what the channel plays).

        Parameters
        ----------
        layer : {"follow", "sources", "clip"}
        channels : sequence of int, optional
            0-based; None = every channel.
        intensity, balance : float, optional
            Validated like :meth:`set_knob`.
        at_frame : int, optional
            Stream frame of the move (exact); None = now.
        glide_s : float, optional
            Glide of this move (None: the channel's glide).
        """
        index = self._driving_index(layer)
        wanted = (("balance", balance), ("intensity", intensity))
        moves = [(name, self.validate_knob(name, value)) for name, value in wanted if value is not None]
        if glide_s is not None:
            glide_s = check_range("glide", glide_s, 0.0, self.limits.glide_max_s)
        chans = self._channel_list(channels)
        events: list[KnobEvent] = []
        with self._lock:
            takeover = [c for c in chans if index > self._top[c]]
            if takeover:
                self._submit(SetLayer(index, self._engine_channels(tuple(takeover)), at_frame))
            for c in chans:
                if index not in self._layers[c]:
                    self._layers[c][index] = {n: getattr(self._state[c], n) for n in KNOB_NAMES}
            for name, value in moves:
                command = SetKnob(name, value, self._engine_channels(chans), at_frame, glide_s, index)  # type: ignore[arg-type]
                self._submit(command)
                for c in chans:
                    self._layers[c][index][name] = value
            for c in chans:
                if c in takeover:
                    self._top[c] = index
                    self._show_top(c, source, events)
                elif self._top[c] == index:
                    for name, value in moves:
                        if getattr(self._state[c], name) != value:
                            self._state[c] = replace(self._state[c], **{name: value})  # type: ignore[arg-type]
                            events.append(KnobEvent(c, name, value, source))
            listeners = list(self._listeners) if events else []
        _notify(listeners, events)

    def release(
        self,
        layer: str,
        *,
        channels: Sequence[int] | None = None,
        glide_s: float | None = None,
        at_frame: int | None = None,
        source: str = "api",
    ) -> None:
        """Deactivate a driving layer on channels; where it drove, glide to the next layer's targets.

        Parameters
        ----------
        layer : {"follow", "sources", "clip"}
        channels : sequence of int, optional
        glide_s : float, optional
            Glide to the next layer's targets (None: the channel's glide).
        at_frame : int, optional
            Stream frame of the hand-over; None = now.
        """
        index = self._driving_index(layer)
        if glide_s is not None:
            glide_s = check_range("glide", glide_s, 0.0, self.limits.glide_max_s)
        chans = self._channel_list(channels)
        events: list[KnobEvent] = []
        with self._lock:
            for c in chans:
                if self._layers[c].pop(index, None) is None or self._top[c] != index:
                    continue
                top = max(self._layers[c], default=0)
                values = self._knobs[c] if top == 0 else self._layers[c][top]
                self._submit(SetLayer(top, (c,), at_frame))
                for name in ("balance", "intensity"):
                    self._submit(SetKnob(name, values[name], (c,), at_frame, glide_s, top))
                self._top[c] = top
                self._show_top(c, source, events)
            listeners = list(self._listeners) if events else []
        _notify(listeners, events)

    def cancel_scheduled(self, layer: str, *, channels: Sequence[int] | None = None) -> None:
        """Drop a driving layer's timetagged moves still waiting in the engine, on channels."""
        index = self._driving_index(layer)
        chans = self._channel_list(channels)
        with self._lock:
            self._submit(CancelLayer(index, self._engine_channels(chans)))

    def driver(self, channel: int) -> str:
        """Name of the layer driving a channel's knobs (0-based channel)."""
        c = self._channel_list([channel])[0]
        with self._lock:
            return LAYER_NAMES[self._top[c]]

    def layer_targets(self, layer: str, channel: int) -> tuple[float, float] | None:
        """(intensity, balance) a layer holds for a channel; None where the layer is not active."""
        index = self.layer_index(layer)
        c = self._channel_list([channel])[0]
        with self._lock:
            values = self._knobs[c] if index == 0 else self._layers[c].get(index)
            return None if values is None else (values["intensity"], values["balance"])

    def _submit(self, command: Command) -> None:
        """With the lock held: hand a command to the engine and remember its sequence number."""
        self._last_seq = max(self._last_seq, self.engine.submit(command))

    # ------------------------------------------------------------------ presets
    def load_preset(
        self, name: str, *, channels: Sequence[int] | None = None, at_frame: int | None = None, source: str = "api"
    ) -> PresetLike:
        """Glide channels to a preset's knobs (with the preset's glide, if it has one)."""
        if self.preset_resolver is None:
            raise PresetError("no preset library is loaded")
        preset = self.preset_resolver(name)
        chans = self._channel_list(channels)
        glide = None if preset.glide_ms is None else preset.glide_ms / 1000.0
        self.set_knob("balance", preset.balance, channels=chans, at_frame=at_frame, glide_s=glide, source=source)
        self.set_knob("intensity", preset.intensity, channels=chans, at_frame=at_frame, glide_s=glide, source=source)
        self._update(chans, "preset", preset.name, source)
        return preset

    def reapply_preset(self, name: str, *, source: str = "reload") -> tuple[int, ...]:
        """Re-apply a (changed) preset on every channel currently playing it; returns those channels."""
        with self._lock:
            chans = tuple(c for c, s in enumerate(self._state) if s.preset == name)
        if chans:
            self.load_preset(name, channels=chans, source=source)
        return chans

    # ------------------------------------------------------------------ queries
    def state(self) -> tuple[ChannelState, ...]:
        """Target state of every channel (a snapshot)."""
        with self._lock:
            return tuple(self._state)

    def get(self, name: str, channel: int = 0) -> float | bool | str | tuple[float, float] | None:
        """One value of one channel: intensity, balance, texture ((intensity, balance) it plays),
        glide (s), mute, preset, driver (the layer driving its knobs)."""
        c = self._channel_list([channel])[0]
        with self._lock:
            state = self._state[c]
            driver = LAYER_NAMES[self._top[c]]
        fields: dict[str, float | bool | str | tuple[float, float] | None] = {
            "intensity": state.intensity,
            "balance": state.balance,
            "texture": (state.intensity, state.balance),
            "glide": state.glide_s,
            "mute": state.muted,
            "preset": state.preset,
            "driver": driver,
        }
        if name not in fields:
            raise ParameterError(f"unknown setting {name!r}; known: {', '.join(fields)}")
        return fields[name]

    def subscribe(self, listener: Listener) -> Callable[[], None]:
        """Call ``listener(event)`` on every change, from the thread making it; returns an unsubscribe function."""
        with self._lock:
            self._listeners.append(listener)

        def unsubscribe() -> None:
            with self._lock:
                if listener in self._listeners:
                    self._listeners.remove(listener)

        return unsubscribe

    def sync(self, timeout_s: float = 2.0) -> bool:
        """Wait until the engine applied every command submitted so far (True) or the timeout passed."""
        target = self._last_seq
        deadline = time.monotonic() + timeout_s
        while self.engine.applied_seq < target:
            if time.monotonic() >= deadline:
                return False
            time.sleep(0.0005)
        return True
