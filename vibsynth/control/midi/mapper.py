"""MIDI messages -> :class:`~vibsynth.control.controller.Controller` calls (pure: no ports, no threads).

:class:`MidiMapper` turns :class:`mido.Message` objects into knob moves. It knows
nothing about ports or files, so the live input (:mod:`vibsynth.control.midi`),
offline rendering of MIDI files and the tests all feed it the same way:
``mapper.handle(msg, at_frame=None)``.

Default map (``midi:`` config section; see ``docs/midi.md``)
-------------------------------------------------------------
===============================  =============================================
message                          effect
===============================  =============================================
CC 11 (expression)               intensity (gate mode: scales the note level)
CC 74 (brightness), CC 1 (mod)   balance over the live balance range
pitch bend                       balance offset, +-``pitch_bend_range`` at full bend
CC n (0-31) + CC n+32            14-bit controller (MSB resets the LSB to 0)
NRPN (CC 99/98, data 6/38)       ``nrpn: {intensity: [1, 0], balance: [1, 1]}``
note on / off (gate mode)        start / release the texture; stacked notes
channel pressure / poly AT       intensity (MPE: replaces velocity; else max)
program change                   preset (``program:`` field, else sorted order)
CC 120 / 123 (and 124-127)       silence the channel's actuators immediately
CC 121 (reset all controllers)   bend 0, expression 1, pressure cleared
system reset / stop              silence everything immediately
sysex, unknown CCs, bad data     ignored and counted (``controller.count_error``)
===============================  =============================================

Range handling (validation at the edge)
---------------------------------------
Every value is clamped into the controller's accepted range *before* the
controller is called: intensity into [0, 1], balance into
``[controller.limits.balance_min, balance_max]``. A controller overshoot, an
extreme pitch bend on top of a bright CC or a binding with an out-of-range
``range:`` therefore never raises :class:`~vibsynth.errors.ParameterError`.

Balance controllers map the raw value *centred*: raw 0 -> the range's low end,
the centre (64, or 8192 for 14-bit) -> balance 0 (the mean spectrum), the top
(127 / 16383) -> the high end; each half is linear. So a mod wheel at rest is
the darkest texture, and CC 74 at its usual centre 64 is exactly neutral.

Actuator state
--------------
Gate logic lives per *actuator* channel, not per MIDI channel: a note on MIDI
channel c is held on every actuator channel that c maps to, and an actuator
keeps sounding until the last note held on it (from any MIDI channel) is
released. This makes note stacking, MPE (one note per MIDI channel, several
MIDI channels on one actuator) and overlapping channel maps behave the same.
"""

from __future__ import annotations

import time
from collections import Counter
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

import mido

from vibsynth.control.clips import player_of
from vibsynth.control.follow import follower_of
from vibsynth.control.midi.bindings import (
    _NOTES_OFF_CCS,
    _REALTIME,
    CC_DATA_DEC,
    CC_DATA_INC,
    CC_DATA_LSB,
    CC_DATA_MSB,
    CC_NRPN_LSB,
    CC_NRPN_MSB,
    CC_RESET_CONTROLLERS,
    CC_RPN_LSB,
    CC_RPN_MSB,
    FOLLOW_GAIN_RANGE_DB,
    Binding,
    MidiSettings,
    check_learn_knob,
    scale_raw,
)
from vibsynth.control.midi.clipnotes import CC_SUSTAIN, ClipNotes
from vibsynth.errors import ParameterError, PresetError


class ControllerLike(Protocol):
    """What the mapper needs of :class:`~vibsynth.control.controller.Controller`."""

    @property
    def limits(self) -> Any: ...

    @property
    def channels(self) -> int: ...

    def set_knob(
        self,
        name: str,
        value: float,
        *,
        channels: Sequence[int] | None = None,
        at_frame: int | None = None,
        glide_s: float | None = None,
        source: str = "api",
    ) -> float: ...

    def load_preset(
        self, name: str, *, channels: Sequence[int] | None = None, at_frame: int | None = None, source: str = "api"
    ) -> Any: ...

    def panic(self, *, source: str = "api") -> None: ...

    def count_error(self, kind: str) -> None: ...

    def state(self) -> tuple[Any, ...]: ...


@dataclass
class _Note:
    midi_channel: int
    note: int
    level: float
    pressure: float | None = None


@dataclass
class _Actuator:
    held: list[_Note] = field(default_factory=list)
    expression: float = 1.0  # gate mode: scales the note level
    level: float | None = None  # continuous mode: intensity from CCs
    base_balance: float | None = None
    bend: float = 0.0  # balance offset (knob units)
    sent: dict[str, float] = field(default_factory=dict)


@dataclass
class _MidiChannel:
    msb: dict[int, int] = field(default_factory=dict)
    lsb_seen: set[int] = field(default_factory=set)
    param: int | None = None  # active NRPN number; None = none or an RPN
    data_msb: int = 0
    data_lsb_seen: set[int] = field(default_factory=set)
    nrpn_msb: int | None = None
    nrpn_lsb: int | None = None
    last_move: dict[Any, float] = field(default_factory=dict)


LearnCallback = Callable[[Binding, tuple[Binding, ...]], None]


class MidiMapper:
    """Translate MIDI messages into controller calls.

    Parameters
    ----------
    controller : Controller
    settings : MidiSettings
    presets : object, optional
        Preset library with ``names()``, ``get(name)`` and ``by_program(n)``.
    source : str
        ``source`` given to the controller (shown to subscribers).
    clock : callable, optional
        Seconds, used for adaptive CC smoothing of live messages (default
        :func:`time.monotonic`); messages with ``at_frame`` use the frame instead.

    Notes
    -----
    Adaptive CC smoothing: a controller move glides over the time since the
    previous move of the same controller on the same MIDI channel, at most
    ``settings.cc_glide_max_s`` (first move: the channel's glide). A slow 7-bit
    sweep therefore becomes a continuous ramp instead of a staircase of short
    glides, while fast moves stay tight.

    Not thread-safe: one input thread calls :meth:`handle`; other threads use
    :meth:`learn` (only sets a flag) and :meth:`release_all`.
    """

    def __init__(
        self,
        controller: ControllerLike,
        settings: MidiSettings,
        *,
        presets: Any = None,
        source: str = "midi",
        clock: Callable[[], float] = time.monotonic,
        clip_notes: ClipNotes | None = None,
    ) -> None:
        self.controller = controller
        self.settings = settings
        self.clip_notes = clip_notes  # notes that play haptic clips (control/midi/clipnotes.py)
        self.presets = presets
        self.source = source
        self.clock = clock
        self.counts: Counter[str] = Counter()
        self.last_error: str | None = None
        self.driven: set[int] = set()
        self._act = [_Actuator() for _ in range(controller.channels)]
        self._chan = [_MidiChannel() for _ in range(16)]
        self._learn: str | None = None
        self._on_learned: LearnCallback | None = None
        self.set_bindings(settings.bindings)
        #: Controllers bound to source coordinates (control/spatial/midi.py), offered every CC first
        #: (before the channel map and MIDI learn).
        self.positions: Any = None

    # ------------------------------------------------------------------ bindings and learn
    @property
    def bindings(self) -> tuple[Binding, ...]:
        return self._bindings

    def set_bindings(self, bindings: Iterable[Binding]) -> None:
        """Replace the bindings (takes effect for the next message)."""
        self._bindings = tuple(bindings)
        by_cc: dict[int, list[Binding]] = {}
        by_nrpn: dict[int, list[Binding]] = {}
        for b in self._bindings:
            if b.cc is not None:
                by_cc.setdefault(b.cc, []).append(b)
            if b.nrpn is not None:
                by_nrpn.setdefault(b.nrpn, []).append(b)
        self._by_cc, self._by_nrpn = by_cc, by_nrpn

    def learn(self, knob: str, on_learned: LearnCallback | None = None) -> None:
        """Bind the next moved controller (CC or NRPN) to ``knob``.

        ``on_learned(binding, all_bindings)`` is called from the input thread once
        it happened. The controller is taken off any other knob.

        Raises
        ------
        ParameterError
            Unknown knob.
        """
        check_learn_knob(knob)
        self._on_learned = on_learned
        self._learn = knob

    @property
    def learning(self) -> str | None:
        """The knob waiting for a controller, or None."""
        return self._learn

    def _maybe_learn(self, cc: int | None, nrpn: int | None) -> None:
        knob = self._learn
        if knob is None:
            return
        self._learn = None
        new = Binding(knob, cc=cc, nrpn=nrpn)
        kept = [b for b in self._bindings if not b.same_source(new)]
        self.set_bindings([new, *kept])
        self.counts["learned"] += 1
        if self._on_learned is not None:
            self._on_learned(new, self._bindings)

    # ------------------------------------------------------------------ entry points
    def handle_bytes(self, data: bytes | Sequence[int], *, at_frame: int | None = None) -> bool:
        """Parse raw MIDI bytes and :meth:`handle` them; unparsable data is counted."""
        try:
            msg = mido.Message.from_bytes(list(data))
        except (ValueError, TypeError, IndexError, KeyError):  # mido raises IndexError on truncated data
            self._reject("midi_bad")
            return False
        return self.handle(msg, at_frame=at_frame)

    def handle(self, msg: mido.Message, *, at_frame: int | None = None) -> bool:
        """Apply one message; return True if it was understood (even if it changed nothing).

        Parameters
        ----------
        msg : mido.Message
        at_frame : int, optional
            Stream frame at which the change applies (offline rendering); None = now.
        """
        kind = msg.type
        self.counts[kind] += 1
        try:
            if kind in ("reset", "stop"):
                self.silence(None, at_frame=at_frame)
                if kind == "reset":
                    self._reset_controllers(range(16))
                return True
            if kind in _REALTIME:
                return True
            if kind == "sysex":
                self._reject("midi_sysex")
                return False
            channel = getattr(msg, "channel", None)
            if channel is None:
                self._reject("midi_unknown")
                return False
            if self.clip_notes is not None and self._clip_message(msg, kind, at_frame):
                return True
            if kind == "control_change" and self.positions is not None:  # source coordinates: any MIDI channel
                if self.positions.handle(channel, msg.control, msg.value, at_frame):
                    return True
            acts = self.settings.channel_map.get(channel)
            if acts is None:
                self._reject("midi_unmapped_channel")
                return False
            handler = getattr(self, "_on_" + kind, None)
            if handler is None:
                self._reject("midi_unknown")
                return False
            return bool(handler(msg, acts, at_frame))
        except (ParameterError, PresetError) as exc:  # e.g. unknown preset; never raised to the port
            self._reject("midi_rejected")
            self.last_error = str(exc)
            return False

    def _reject(self, kind: str) -> None:
        self.counts[kind] += 1
        self.controller.count_error(kind)

    def _clip_message(self, msg: mido.Message, kind: str, at_frame: int | None) -> bool:
        """Notes of the clip map, the sustain pedal and all-notes-off for the clips; True when done with ``msg``."""
        notes = self.clip_notes
        assert notes is not None
        if kind == "note_on" and msg.velocity > 0:
            return notes.note_on(msg, self.settings.channel_map, at_frame)
        if kind in ("note_on", "note_off"):
            return notes.note_off(msg, at_frame)
        if kind == "control_change":
            if msg.control in _NOTES_OFF_CCS:
                notes.channel_off(msg.channel, at_frame=at_frame, release_s=self.settings.fade_s)
                return msg.channel not in self.settings.channel_map  # where it maps, the texture is silenced too
            if msg.control == CC_SUSTAIN:
                return notes.pedal(msg.channel, msg.value, at_frame) and CC_SUSTAIN not in self._by_cc
        return False

    # ------------------------------------------------------------------ notes
    def _on_note_on(self, msg: mido.Message, acts: tuple[int, ...], at_frame: int | None) -> bool:
        if msg.velocity == 0:
            return self._on_note_off(msg, acts, at_frame)
        if self.settings.mode != "gate":
            self.counts["note_ignored"] += 1
            return True
        level = (msg.velocity / 127.0) ** self.settings.velocity_curve
        for a in acts:
            held = self._act[a].held
            held[:] = [n for n in held if (n.midi_channel, n.note) != (msg.channel, msg.note)]
            held.append(_Note(msg.channel, msg.note, level))
        self._push(acts, ("intensity",), at_frame, self.settings.attack_s)
        return True

    def _on_note_off(self, msg: mido.Message, acts: tuple[int, ...], at_frame: int | None) -> bool:
        if self.settings.mode != "gate":
            self.counts["note_ignored"] += 1
            return True
        for a in acts:
            held = self._act[a].held
            held[:] = [n for n in held if (n.midi_channel, n.note) != (msg.channel, msg.note)]
        self._push(acts, ("intensity",), at_frame, self._intensity_glide)
        return True

    def _on_aftertouch(self, msg: mido.Message, acts: tuple[int, ...], at_frame: int | None) -> bool:
        pressure = msg.value / 127.0
        if self.settings.mode == "continuous":
            for a in acts:
                self._act[a].level = pressure
        else:
            for a in acts:
                for n in self._act[a].held:
                    if n.midi_channel == msg.channel:
                        n.pressure = pressure
        self._push(acts, ("intensity",), at_frame, None)
        return True

    def _on_polytouch(self, msg: mido.Message, acts: tuple[int, ...], at_frame: int | None) -> bool:
        pressure = msg.value / 127.0
        if self.settings.mode == "continuous":
            return self._on_aftertouch(msg, acts, at_frame)
        for a in acts:
            for n in self._act[a].held:
                if (n.midi_channel, n.note) == (msg.channel, msg.note):
                    n.pressure = pressure
        self._push(acts, ("intensity",), at_frame, None)
        return True

    def _intensity_glide(self, a: int, new: float) -> float | None:
        # note-off to silence releases with the configured release time
        return self.settings.release_s if new == 0.0 and not self._act[a].held else self.settings.attack_s

    # ------------------------------------------------------------------ pitch bend, program change
    def _on_pitchwheel(self, msg: mido.Message, acts: tuple[int, ...], at_frame: int | None) -> bool:
        bend = msg.pitch / (8191.0 if msg.pitch > 0 else 8192.0) * self.settings.pitch_bend_range
        for a in acts:
            self._base_balance(a)
            self._act[a].bend = bend
        self._push(acts, ("balance",), at_frame, None)
        return True

    def _on_program_change(self, msg: mido.Message, acts: tuple[int, ...], at_frame: int | None) -> bool:
        name = self._preset_for_program(msg.program)
        if name is None:
            self._reject("midi_unknown_program")
            return False
        if self.settings.mode == "continuous":
            preset = self.controller.load_preset(name, channels=acts, at_frame=at_frame, source=self.source)
            for a in acts:
                st = self._act[a]
                st.level = float(preset.intensity)
                st.base_balance = float(preset.balance)
                st.bend = 0.0
                st.sent.update(intensity=float(preset.intensity), balance=float(preset.balance))
            self.driven.update(acts)
            return True
        # gate mode: the preset's balance now, its intensity becomes the note scale
        preset = self.presets.get(name)
        glide = None if getattr(preset, "glide_ms", None) is None else preset.glide_ms / 1000.0
        for a in acts:
            self._act[a].base_balance = float(preset.balance)
            self._act[a].expression = float(preset.intensity)
        self._push(acts, ("balance", "intensity"), at_frame, glide)
        return True

    def _preset_for_program(self, program: int) -> str | None:
        if self.presets is None:
            return None
        by_program = getattr(self.presets, "by_program", None)
        preset = by_program(program) if by_program is not None else None
        if preset is not None:
            return str(preset.name)
        names = sorted(self.presets.names())
        return names[program] if program < len(names) else None

    # ------------------------------------------------------------------ controllers
    def _on_control_change(self, msg: mido.Message, acts: tuple[int, ...], at_frame: int | None) -> bool:
        cc, value, ch = msg.control, msg.value, self._chan[msg.channel]
        if cc in _NOTES_OFF_CCS:
            self.silence(acts, at_frame=at_frame)
            return True
        if cc == CC_RESET_CONTROLLERS:
            self._reset_controllers([msg.channel])
            for a in acts:
                st = self._act[a]
                st.bend, st.expression = 0.0, 1.0
                for n in st.held:
                    n.pressure = None
            self._push(acts, ("balance", "intensity"), at_frame, None)
            return True
        if cc in (CC_NRPN_MSB, CC_NRPN_LSB):
            if cc == CC_NRPN_MSB:
                ch.nrpn_msb = value
            else:
                ch.nrpn_lsb = value
            ch.param = None if ch.nrpn_msb is None or ch.nrpn_lsb is None else ch.nrpn_msb * 128 + ch.nrpn_lsb
            if ch.nrpn_msb == 127 and ch.nrpn_lsb == 127:
                ch.param = None  # null parameter
            return True
        if cc in (CC_RPN_MSB, CC_RPN_LSB):  # RPNs are not used; selecting one deselects the NRPN
            ch.param, ch.nrpn_msb, ch.nrpn_lsb = None, None, None
            return True
        if cc in (CC_DATA_MSB, CC_DATA_LSB):
            if ch.param is None:
                self._reject("midi_unknown_nrpn")
                return False
            if cc == CC_DATA_MSB:
                ch.data_msb = value
                raw = value << 7
            else:
                ch.data_lsb_seen.add(ch.param)
                raw = (ch.data_msb << 7) | value
            self._maybe_learn(None, ch.param)
            bindings = self._by_nrpn.get(ch.param)
            if not bindings:
                self._reject("midi_unknown_nrpn")
                return False
            top = 16383
            if ch.param not in ch.data_lsb_seen:  # 7-bit device: MSB only
                raw, top = raw >> 7, 127
            return self._apply(bindings, msg.channel, acts, raw, top, ("nrpn", ch.param), at_frame)
        if cc in (CC_DATA_INC, CC_DATA_DEC):
            self._reject("midi_unknown")
            return False
        if 32 <= cc < 64 and (cc - 32) in ch.msb and (cc - 32) in self._by_cc:
            msb_cc = cc - 32
            ch.lsb_seen.add(msb_cc)
            raw = (ch.msb[msb_cc] << 7) | value
            return self._apply(self._by_cc[msb_cc], msg.channel, acts, raw, 16383, ("cc", msb_cc), at_frame)
        if self._learn is not None and not (32 <= cc < 64):
            self._maybe_learn(cc, None)
        bindings = self._by_cc.get(cc)
        if not bindings:
            self._reject("midi_unknown_cc")
            return False
        if cc < 32:
            ch.msb[cc] = value
            if cc in ch.lsb_seen:  # 14-bit controller: the MSB resets the LSB to 0
                return self._apply(bindings, msg.channel, acts, value << 7, 16383, ("cc", cc), at_frame)
        return self._apply(bindings, msg.channel, acts, value, 127, ("cc", cc), at_frame)

    def _reset_controllers(self, midi_channels: Iterable[int]) -> None:
        for c in midi_channels:
            self._chan[c] = _MidiChannel()

    def _apply(
        self,
        bindings: list[Binding],
        midi_channel: int,
        acts: tuple[int, ...],
        raw: int,
        top: int,
        key: Any,
        at_frame: int | None,
    ) -> bool:
        glide = self._cc_glide(midi_channel, key, at_frame)
        applied = False
        for b in bindings:
            if b.channel is not None and b.channel != midi_channel:
                continue
            applied = True
            if b.invert:
                raw = top - raw
            if b.knob == "follow_gain":
                self._follow_gain(b, raw, top)
            elif b.knob == "intensity":
                low = 0.0 if b.low is None else b.low
                high = 1.0 if b.high is None else b.high
                value = _clamp(scale_raw(raw, top, low, high, centred=False), 0.0, 1.0)
                for a in acts:
                    if self.settings.mode == "gate":
                        self._act[a].expression = value
                    else:
                        self._act[a].level = value
                self._push(acts, ("intensity",), at_frame, glide)
            else:
                lim = self.controller.limits
                low = lim.balance_min if b.low is None else b.low
                high = lim.balance_max if b.high is None else b.high
                value = scale_raw(raw, top, low, high, centred=True)
                for a in acts:
                    self._act[a].base_balance = value
                self._push(acts, ("balance",), at_frame, glide)
        if not applied:
            self._reject("midi_unknown_cc")
        return applied

    def _follow_gain(self, b: Binding, raw: int, top: int) -> None:
        """Live Follow's gain from a controller (counted as ``midi_no_follow`` while follow does not run)."""
        follower = follower_of(self.controller)
        if follower is None:
            self._reject("midi_no_follow")
            return
        low = FOLLOW_GAIN_RANGE_DB[0] if b.low is None else b.low
        high = FOLLOW_GAIN_RANGE_DB[1] if b.high is None else b.high
        follower.set_gain(scale_raw(raw, top, low, high, centred=False))

    def _cc_glide(self, midi_channel: int, key: Any, at_frame: int | None) -> float | None:
        max_s = self.settings.cc_glide_max_s
        if max_s <= 0:
            return None
        fs = float(getattr(getattr(self.controller, "engine", None), "fs", 0.0) or 0.0)
        now = at_frame / fs if at_frame is not None and fs > 0 else self.clock()
        moves = self._chan[midi_channel].last_move
        last = moves.get(key)
        moves[key] = now
        if last is None or now <= last:
            return None
        return min(now - last, max_s)

    # ------------------------------------------------------------------ silence
    def silence(self, acts: Iterable[int] | None, *, at_frame: int | None = None) -> None:
        """Silence actuators immediately (all notes off, intensity to 0 with the short fade, their clips stopped).

        ``acts=None`` means every actuator; without ``at_frame`` that is
        :meth:`Controller.panic` (which also drops scheduled commands).
        """
        targets = tuple(range(len(self._act))) if acts is None else tuple(acts)
        every = len(set(targets)) == len(self._act)
        if self.clip_notes is not None:
            self.clip_notes.all_off(None if every else targets, at_frame=at_frame, release_s=self.settings.fade_s)
        player = player_of(self.controller)
        if player is not None and not (every and at_frame is None):  # (a panic stops every clip itself)
            player.stop(channels=targets, release_s=self.settings.fade_s, at_frame=at_frame, source=self.source)
        for a in targets:
            st = self._act[a]
            st.held.clear()
            st.level = 0.0 if self.settings.mode == "continuous" else st.level
            st.sent["intensity"] = 0.0
        if every and at_frame is None:
            self.controller.panic(source=self.source)
        else:
            self.controller.set_knob(
                "intensity", 0.0, channels=targets, at_frame=at_frame, glide_s=self.settings.fade_s, source=self.source
            )

    def release_all(self, acts: Iterable[int] | None = None, *, at_frame: int | None = None) -> tuple[int, ...]:
        """Release every held note (as if all note-offs arrived); return the actuators released.

        Used when a port vanishes: no note stays stuck. Continuous-mode levels are kept.
        """
        targets = tuple(range(len(self._act))) if acts is None else tuple(acts)
        if self.clip_notes is not None and acts is None:
            self.clip_notes.release_all()
        released = tuple(a for a in targets if self._act[a].held)
        for a in released:
            self._act[a].held.clear()
        if released:
            self._push(released, ("intensity",), at_frame, self._intensity_glide)
        return released

    # ------------------------------------------------------------------ output
    def _base_balance(self, a: int) -> float:
        st = self._act[a]
        if st.base_balance is None:
            st.base_balance = float(self.controller.state()[a].balance) - st.bend
        return st.base_balance

    def _target(self, a: int, knob: str) -> float | None:
        st = self._act[a]
        if knob == "balance":
            lim = self.controller.limits
            return _clamp(self._base_balance(a) + st.bend, lim.balance_min, lim.balance_max)
        if self.settings.mode == "continuous":
            return None if st.level is None else _clamp(st.level, 0.0, 1.0)
        if not st.held:
            return 0.0
        note = st.held[-1]  # last-note priority
        level = note.level
        if note.pressure is not None:
            level = note.pressure if self.settings.mpe else max(level, note.pressure)
        return _clamp(level * st.expression, 0.0, 1.0)

    def _push(
        self,
        acts: tuple[int, ...],
        knobs: tuple[str, ...],
        at_frame: int | None,
        glide: float | None | Callable[[int, float], float | None],
    ) -> None:
        """Send changed targets, one controller call per (knob, value, glide) group.

        ``glide`` is seconds, None (the channel's glide), or ``glide(actuator, value)``.
        """
        for knob in knobs:
            groups: dict[tuple[float, float | None], list[int]] = {}
            for a in acts:
                value = self._target(a, knob)
                st = self._act[a]
                if value is None:
                    continue
                if knob == "intensity" and self.settings.mode == "gate" and not st.held and "intensity" not in st.sent:
                    continue  # never touched by a note: leave other sources' intensity alone
                if st.sent.get(knob) == value:
                    continue
                g = glide(a, value) if callable(glide) else glide
                st.sent[knob] = value
                groups.setdefault((value, g), []).append(a)
            for (value, g), chans in groups.items():
                self.controller.set_knob(knob, value, channels=chans, at_frame=at_frame, glide_s=g, source=self.source)
                self.driven.update(chans)


def _clamp(value: float, low: float, high: float) -> float:
    return low if value < low else high if value > high else float(value)
