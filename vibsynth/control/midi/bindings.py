"""MIDI settings: bindings (CC, 14-bit, NRPN), channel maps, and scaling raw values to knobs."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from vibsynth.errors import ConfigError, ParameterError
from vibsynth.settings.values import BINDABLE_CC_MAX

if TYPE_CHECKING:
    from vibsynth.settings.models_config import Midi

#: What a MIDI controller can be bound to (and learned for): the two knobs and live Follow's gain.
KNOBS = ("intensity", "balance", "follow_gain")
#: follow_gain: the dB a controller's 0..max spans when its binding gives no range.
FOLLOW_GAIN_RANGE_DB = (-24.0, 24.0)
#: Bound to nothing by default: MIDI learn writes them into a config file only once bound.
OPTIONAL_KNOBS = ("follow_gain",)


def check_learn_knob(knob: str) -> None:
    """Raise :class:`ParameterError` unless ``knob`` can be MIDI-learned."""
    if knob not in KNOBS:
        raise ParameterError(f"cannot learn {knob!r}; knobs are {', '.join(KNOBS)}")


# Controller numbers with a fixed meaning (never bound, never learned).
CC_DATA_MSB, CC_DATA_LSB = 6, 38
CC_DATA_INC, CC_DATA_DEC = 96, 97
CC_NRPN_LSB, CC_NRPN_MSB = 98, 99
CC_RPN_LSB, CC_RPN_MSB = 100, 101
CC_ALL_SOUND_OFF, CC_RESET_CONTROLLERS, CC_ALL_NOTES_OFF = 120, 121, 123
_NOTES_OFF_CCS = frozenset({CC_ALL_SOUND_OFF, CC_ALL_NOTES_OFF, 124, 125, 126, 127})
_PARAMETER_CCS = frozenset(
    {CC_DATA_MSB, CC_DATA_LSB, CC_DATA_INC, CC_DATA_DEC, CC_NRPN_LSB, CC_NRPN_MSB, CC_RPN_LSB, CC_RPN_MSB}
)
_REALTIME = frozenset(
    {"clock", "start", "continue", "active_sensing", "songpos", "song_select", "quarter_frame", "tune_request"}
)
DEFAULT_NRPN = {"intensity": [1, 0], "balance": [1, 1]}


@dataclass(frozen=True)
class Binding:
    """One controller bound to a knob.

    Attributes
    ----------
    knob : {"intensity", "balance"}
    cc : int or None
        Controller number 0-119 (0-31 also accept an LSB on ``cc + 32``).
    nrpn : int or None
        14-bit NRPN parameter number (``msb * 128 + lsb``).
    channel : int or None
        0-based MIDI channel this binding listens to; None = every channel.
    low, high : float or None
        Knob values at the controller's minimum and maximum; None = the knob's
        full live range (intensity 0..1, balance the controller's limits).
    invert : bool
        Swap the ends (controller maximum -> low end).
    shorthand : bool
        Made from the ``midi.nrpn`` shorthand key rather than a ``midi.mapping`` entry:
        MIDI learn does not write it into ``midi.mapping`` (the shorthand key keeps it).
        Not part of equality.
    """

    knob: str
    cc: int | None = None
    nrpn: int | None = None
    channel: int | None = None
    low: float | None = None
    high: float | None = None
    invert: bool = False
    shorthand: bool = field(default=False, compare=False)

    def to_config(self) -> dict[str, Any]:
        """The binding as a ``midi.mapping`` list entry (1-based channel)."""
        out: dict[str, Any] = {}
        if self.cc is not None:
            out["cc"] = self.cc
        if self.nrpn is not None:
            out["nrpn"] = [self.nrpn // 128, self.nrpn % 128]
        if self.channel is not None:
            out["channel"] = self.channel + 1
        if self.low is not None and self.high is not None:
            out["range"] = [self.low, self.high]
        if self.invert:
            out["invert"] = True
        return out

    def same_source(self, other: Binding) -> bool:
        """Whether both listen to the same controller (ignoring the knob and range)."""
        return (self.cc, self.nrpn, self.channel) == (other.cc, other.nrpn, other.channel)


def _int_in(value: Any, low: int, high: int, where: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not (low <= value <= high):
        raise ConfigError(f"{where}: expected an integer {low}..{high}, got {value!r}")
    return value


def _nrpn_number(value: Any, where: str) -> int:
    if isinstance(value, (list, tuple)) and len(value) == 2:
        return _int_in(value[0], 0, 127, where) * 128 + _int_in(value[1], 0, 127, where)
    return _int_in(value, 0, 16383, where)


def parse_bindings(mapping: Mapping[str, Any] | None, nrpn: Mapping[str, Any] | None = None) -> tuple[Binding, ...]:
    """Bindings from the ``midi.mapping`` and ``midi.nrpn`` config keys.

    Parameters
    ----------
    mapping : mapping
        ``{knob: [{cc: N, channel: 1-16, invert: bool, range: [low, high]} | {nrpn: N | [msb, lsb]}, ...]}``.
    nrpn : mapping, optional
        ``{knob: N | [msb, lsb]}``: shorthand NRPN bindings (default :data:`DEFAULT_NRPN`).

    Returns
    -------
    bindings : tuple of Binding

    Raises
    ------
    ConfigError
        Unknown knob, controller number out of range, malformed entry.
    """
    out: list[Binding] = []
    for knob, entries in (mapping or {}).items():
        where = f"midi.mapping.{knob}"
        if knob not in KNOBS:
            raise ConfigError(f"{where}: unknown knob; knobs are {', '.join(KNOBS)}")
        if entries is None:
            continue
        if isinstance(entries, Mapping):
            entries = [entries]
        for i, entry in enumerate(entries):
            w = f"{where}[{i}]"
            if not isinstance(entry, Mapping) or ("cc" in entry) == ("nrpn" in entry):
                raise ConfigError(f"{w}: expected {{cc: 0-{BINDABLE_CC_MAX}}} or {{nrpn: N}}, got {entry!r}")
            cc = _int_in(entry["cc"], 0, BINDABLE_CC_MAX, w + ".cc") if "cc" in entry else None
            if cc is not None and cc in _PARAMETER_CCS:
                raise ConfigError(f"{w}.cc: controller {cc} is reserved for NRPN/RPN data")
            num = _nrpn_number(entry["nrpn"], w + ".nrpn") if "nrpn" in entry else None
            channel = entry.get("channel")
            channel = None if channel is None else _int_in(channel, 1, 16, w + ".channel") - 1
            low = high = None
            if entry.get("range") is not None:
                rng = entry["range"]
                try:
                    low, high = (float(v) for v in rng)
                except (TypeError, ValueError):
                    raise ConfigError(f"{w}.range: expected [low, high], got {rng!r}") from None
                if not (math.isfinite(low) and math.isfinite(high)):
                    raise ConfigError(f"{w}.range: must be finite, got {rng!r}")
            invert = entry.get("invert", False)
            if not isinstance(invert, bool):
                raise ConfigError(f"{w}.invert: expected true or false, got {invert!r}")
            out.append(Binding(knob, cc, num, channel, low, high, invert))
    for knob, number in (DEFAULT_NRPN if nrpn is None else nrpn or {}).items():
        if knob not in KNOBS:
            raise ConfigError(f"midi.nrpn.{knob}: unknown knob; knobs are {', '.join(KNOBS)}")
        if number is not None:
            out.append(Binding(knob, nrpn=_nrpn_number(number, f"midi.nrpn.{knob}"), shorthand=True))
    return tuple(out)


def parse_channel_map(raw: Any, channels: int, *, mpe: bool = False) -> dict[int, tuple[int, ...]]:
    """MIDI channel -> actuator channels, both 0-based.

    Parameters
    ----------
    raw : mapping or None
        ``{midi_channel (1-16): "all" | actuator (1-based) | [actuators]}``;
        None or empty = omni (every MIDI channel drives every actuator).
    channels : int
        Actuator channels of the engine.
    mpe : bool
        MPE lower zone: channel 1 is the master (all actuators); member channels
        2-16 not named in ``raw`` map round-robin onto the actuators
        (channel 2 -> actuator 1, channel 3 -> actuator 2, ...).

    Returns
    -------
    channel_map : dict
        Unmapped MIDI channels are absent.

    Raises
    ------
    ConfigError
    """
    every = tuple(range(channels))
    out: dict[int, tuple[int, ...]] = {}
    if not raw:
        out = {c: every for c in range(16)}
    else:
        if not isinstance(raw, Mapping):
            raise ConfigError(f"midi.channel_map: expected a mapping {{1: all}}, got {raw!r}")
        for key, value in raw.items():
            try:
                midi_ch = int(key)
            except (TypeError, ValueError):
                raise ConfigError(f"midi.channel_map: MIDI channel must be 1-16, got {key!r}") from None
            where = f"midi.channel_map.{key}"
            _int_in(midi_ch, 1, 16, where)
            if value == "all" or value is None:
                out[midi_ch - 1] = every
                continue
            values = value if isinstance(value, (list, tuple)) else [value]
            acts = tuple(sorted({_int_in(v, 1, channels, where) - 1 for v in values}))
            if not acts:
                raise ConfigError(f"{where}: no actuator channel given")
            out[midi_ch - 1] = acts
    if mpe:
        out.setdefault(0, every)
        for midi_ch in range(1, 16):
            out.setdefault(midi_ch, ((midi_ch - 1) % channels,))
    return out


@dataclass(frozen=True)
class MidiSettings:
    """The ``midi:`` config section, validated.

    Attributes
    ----------
    mode : {"gate", "continuous"}
    release_s, attack_s : float or None
        Note-off release glide to 0 / note-on glide (None = the channel's glide).
    velocity_curve : float
        Note level ``(velocity / 127) ** velocity_curve``.
    pitch_bend_range : float
        Balance offset at full pitch bend.
    channel_map : dict
        See :func:`parse_channel_map`.
    mpe : bool
    bindings : tuple of Binding
    cc_glide_max_s : float
        Upper bound of the adaptive CC smoothing (see :class:`MidiMapper`); 0 disables it.
    fade_s : float
        Fade used by all-notes-off / reset when it must be scheduled at a frame.
    """

    mode: str = "gate"
    release_s: float = 0.15
    attack_s: float | None = None
    velocity_curve: float = 1.0
    pitch_bend_range: float = 0.5
    channel_map: dict[int, tuple[int, ...]] = field(default_factory=lambda: {0: (0,)})
    mpe: bool = False
    bindings: tuple[Binding, ...] = ()
    cc_glide_max_s: float = 0.1
    fade_s: float = 0.01

    @classmethod
    def from_settings(cls, midi: Midi, channels: int, *, fade_ms: float) -> MidiSettings:
        """From the typed ``midi:`` section (its model checked the ranges) for an engine with ``channels`` outputs.

        ``fade_ms`` is ``knobs.mute_fade_ms``.

        Raises
        ------
        ConfigError
            A binding to a controller reserved for NRPN/RPN data (CC 6, 38, 96-101).
        """
        return cls(
            mode=midi.mode,
            release_s=midi.release_ms / 1000.0,
            attack_s=None if midi.attack_ms is None else midi.attack_ms / 1000.0,
            velocity_curve=midi.velocity_curve,
            pitch_bend_range=midi.pitch_bend_range,
            channel_map=parse_channel_map(midi.channel_map, channels, mpe=midi.mpe),
            mpe=midi.mpe,
            bindings=parse_bindings(midi.mapping.model_dump(exclude_none=True), midi.nrpn.model_dump()),
            cc_glide_max_s=midi.cc_glide_max_ms / 1000.0,
            fade_s=fade_ms / 1000.0,
        )


def scale_raw(raw: int, top: int, low: float, high: float, *, centred: bool) -> float:
    """Map a raw controller value 0..top onto [low, high].

    Parameters
    ----------
    raw : int
    top : int
        127 (7-bit) or 16383 (14-bit).
    low, high : float
    centred : bool
        Map the centre value (64 / 8192) to 0 when 0 lies inside (low, high)
        (each half linear); otherwise linear over the whole range.

    Returns
    -------
    value : float
    """
    raw = min(max(raw, 0), top)
    if centred and low < 0.0 < high:
        centre = (top + 1) // 2
        if raw >= centre:
            return high * (raw - centre) / (top - centre)
        return low * (centre - raw) / centre
    return low + (high - low) * raw / top
