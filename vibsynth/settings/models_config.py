"""The configuration, typed: every section and key, its default, range and help text, in one place.

``vibsynth/data/config/default.yaml`` is the annotated, human-facing copy of the defaults
(a test checks it equals these models key by key); ``docs/config.md``'s key tables and
``vibsynth/data/schema/config.schema.json`` are generated from these models
(``python scripts/gen_settings_docs.py``).
"""

from __future__ import annotations

import re
from collections.abc import Callable
from typing import Annotated, Any, Literal

from pydantic import BeforeValidator, ConfigDict, Discriminator, Field, Tag, ValidationInfo, model_validator
from pydantic_core import PydanticCustomError

from vibsynth.dsp.filterbank import MIN_RATE_HZ
from vibsynth.limits import ACTUATOR_BOOST_MAX_DB, GLIDE_MAX_MS, MAX_CHANNELS, OSC_PREFIX_MAX, SCHEDULE_CAPACITY_MAX
from vibsynth.settings.fields import Section, SettingsModel, ValueModel, cross_problem, problem, setting
from vibsynth.settings.models_clip_config import Clips
from vibsynth.settings.models_discovery import Discovery
from vibsynth.settings.models_follow import Follow
from vibsynth.settings.models_lab import Lab
from vibsynth.settings.models_midi_clips import MidiClips
from vibsynth.settings.models_sources import Sources, knob_conflict
from vibsynth.settings.models_studio import Studio
from vibsynth.settings.models_vrchat import Vrchat, target_of
from vibsynth.settings.values import (
    BINDABLE_CC_MAX,
    CC_MAX,
    KNOB_BALANCE_LIMIT,
    MIDI_CHANNELS,
    NRPN_MAX,
    Points,
    check_allow_list,
    check_bindings,
    check_channel_list,
    check_midi_channel_map,
    check_nrpn_map,
    null_means,
)

__all__ = [
    "CONFIG_VERSION",
    "PROFILE_NAME",
    "CHANNEL_NAME",
    "MAX_CHANNELS",
    "RESPONSE_POINTS",
    "SPEED_POINTS",
    "ResponsePoint",
    "Audio",
    "Bank",
    "Knobs",
    "Actuator",
    "Osc",
    "MidiBinding",
    "NrpnNumbers",
    "MidiMapping",
    "Midi",
    "Speed",
    "Presets",
    "ChannelPosition",
    "check_layout",
    "inline_layout_problem",
    "FILE_CHECKS",
    "FileCheck",
    "VibsynthConfig",
]

CONFIG_VERSION = 1
#: Names of actuator profiles (and their files): letters, digits, '.', '_', '-'.
PROFILE_NAME = r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,63}$"
#: Names of layout channels: lower-case words and numbers joined by '-' (``thumb``, ``back-3-2``).
CHANNEL_NAME = r"^[a-z0-9]+(-[a-z0-9]+)*$"
#: An actuator's frequency response: [Hz, dB] points.
RESPONSE_POINTS = Points("Hz", 0.0, True, "dB", -60.0, 60.0, 1)
#: The OSC /speed curve: [mm/s, intensity] points.
SPEED_POINTS = Points("mm/s", 0.0, False, "intensity", 0.0, 1.0, 2)

ResponsePoint = Annotated[
    list[float], Field(min_length=2, max_length=2, json_schema_extra=RESPONSE_POINTS.pair_schema())
]
_SpeedPoint = Annotated[list[float], Field(min_length=2, max_length=2, json_schema_extra=SPEED_POINTS.pair_schema())]
_Nrpn = (
    Annotated[int, Field(ge=0, le=NRPN_MAX)]
    | Annotated[list[Annotated[int, Field(ge=0, le=CC_MAX)]], Field(min_length=2, max_length=2)]
)
_MIDI_CHANNEL_KEYS = {"propertyNames": {"pattern": "^([1-9]|1[0-6])$"}}


class Audio(Section):
    """``audio:``: the output device and the engine's channels."""

    backend: Annotated[Literal["auto", "sounddevice", "null", "wav"], BeforeValidator(null_means("null"))] = setting(
        "auto",
        "auto / sounddevice / null / wav; auto = sounddevice, else null with a warning",
        schema={"enum": ["auto", "sounddevice", "null", "wav", None], "type": ["string", "null"]},
    )
    device: str | Annotated[int, Field(ge=0)] | None = setting(
        None,
        "name substring or index; null = the host API's default output",
        allowed="a device name substring, an index >= 0, or null",
    )
    host_api: str | None = setting(
        None,
        'e.g. "ALSA", "JACK Audio Connection Kit", "Core Audio", "WASAPI"',
        allowed="a host API name or null",
    )
    rate: int = setting(48000, "sample rate", unit="Hz", ge=int(MIN_RATE_HZ), le=384000)
    block_size: int = setting(128, "frames per callback", unit="frames", ge=16, le=8192)
    latency: Literal["low", "high"] | Annotated[float, Field(gt=0, le=2)] = setting(
        "low", "low / high / seconds (float)", unit="s"
    )
    channels: int = setting(1, "actuator channels rendered by the engine", ge=1, le=MAX_CHANNELS)
    channel_map: Annotated[list[Annotated[int, Field(ge=1)]] | None, BeforeValidator(check_channel_list)] = setting(
        None,
        "list: engine channel i -> device output (1-based); null = 1..channels",
        allowed="null or a list of distinct device outputs (1-based), one per channel",
        schema={"uniqueItems": True},
    )


class Bank(Section):
    """``bank:``: the precomputed noise bank."""

    balance_min: float = setting(
        -3.5, "bottom of the precomputed noise bank's balance grid", unit="(knob units)", ge=-10, le=0
    )
    balance_max: float = setting(3.5, "top of the bank's balance grid", unit="(knob units)", ge=0, le=10)
    levels: int = setting(49, "grid size", ge=2, le=1001)
    loop_seconds: float = setting(4.0, "length of each seamless loop", unit="s", ge=0.5, le=60)
    cache_dir: str | None = setting(
        None,
        'null = the platform cache folder; "" disables the disk cache',
        allowed='a folder path ("" disables the cache) or null',
    )
    seed: int = setting(1, "random phases (same seed, same bank)", ge=0, le=2**32 - 1)


class Knobs(Section):
    """``knobs:``: the intensity mapping, smoothing, limits and the initial state."""

    ceiling_db: float = setting(
        -40.0,
        "80-200 Hz band level at intensity 1 (dB re unit RMS); peaks <= -2 dBFS at any balance",
        unit="dB",
        ge=-120,
        le=0,
    )
    range_db: float = setting(40.0, "intensity (0, 1] spans this many dB below the ceiling", unit="dB", gt=0, le=120)
    glide_ms: float = setting(20.0, "knob smoothing, 0 = jump", unit="ms", ge=0, le=GLIDE_MAX_MS)
    mute_fade_ms: float = setting(10.0, "fade of mute/panic", unit="ms", ge=0, le=1000)
    limiter_ceiling: float = setting(
        0.891, "no output sample exceeds this (|x|), about -1 dBFS", unit="(full scale)", gt=0, le=1
    )
    schedule_capacity: int = setting(
        10000,
        "most timetagged commands waiting at once; more are refused with an error reply and counted (`schedule_full`)",
        ge=1,
        le=SCHEDULE_CAPACITY_MAX,
    )
    balance_min: float = setting(
        -3.5, "live controls are limited to this range", unit="(knob units)", ge=-KNOB_BALANCE_LIMIT, le=0
    )
    balance_max: float = setting(3.5, "top of the live balance range", unit="(knob units)", ge=0, le=KNOB_BALANCE_LIMIT)
    initial_intensity: float = setting(0.0, "silent until a control arrives", ge=0, le=1)
    initial_balance: float = setting(0.0, "balance before any control arrives", unit="(knob units)", ge=-10, le=10)


#: ``actuator.channel_profiles`` as a pattern: ``{n}`` stands for the 1-based channel number.
CHANNEL_PROFILE_FIELD = "{n}"


def check_channel_profiles(value: Any) -> Any:
    """``actuator.channel_profiles``: null, a name pattern with ``{n}``, or a list of profile names or nulls."""
    if value is None:
        return value
    if isinstance(value, str):
        if value.count(CHANNEL_PROFILE_FIELD) != 1 or not re.match(PROFILE_NAME, value.replace("{n}", "1")):
            raise problem(
                f"{value!r} is not a profile name pattern: it needs {{n}} once (the channel number) in a profile "
                "name of letters, digits, . _ - (e.g. vest-ch{n})"
            )
        return value
    if not isinstance(value, list) or not 1 <= len(value) <= MAX_CHANNELS:
        raise problem(f"must be a name pattern like vest-ch{{n}} or a list of 1..{MAX_CHANNELS} profile names or nulls")
    for i, name in enumerate(value):
        if name is not None and not (isinstance(name, str) and re.match(PROFILE_NAME, name)):
            raise problem(f"channel {i + 1}: {name!r} is not a profile name (letters, digits, . _ -) or null", i)
    return value


class Actuator(Section):
    """``actuator:``: the actuator's frequency response, equalised by the bank."""

    profile: str | None = setting(
        "flat",
        "name of a profile in config/actuators/ (flat, hapcoil-example), or null",
        allowed="a profile name or null",
        pattern=PROFILE_NAME,
    )
    response: Annotated[list[ResponsePoint] | None, BeforeValidator(RESPONSE_POINTS.check)] = setting(
        None,
        "explicit points [[Hz, dB], ...], interpolated on log-frequency; overrides profile",
        allowed=RESPONSE_POINTS.allowed(nullable=True),
    )
    max_boost_db: float = setting(
        12.0,
        "the inverse-EQ never boosts more than this above the response's level in the intensity band",
        unit="dB",
        ge=0,
        le=ACTUATOR_BOOST_MAX_DB,
    )
    channel_profiles: Annotated[str | list[str | None] | None, BeforeValidator(check_channel_profiles)] = setting(
        None,
        "each output channel's own profile (equalised by a per-channel trim): a pattern with {n} for the channel "
        "number (vest-ch{n}, as calibrate response --channels all -o vest writes), or a list (channel 1 first; "
        "null = actuator.profile); null = the layout's per-channel profiles, if any",
        allowed="a profile name pattern with {n}, a list of profile names or nulls, or null",
    )


class Osc(Section):
    """``osc:``: the OSC server."""

    enabled: bool = setting(True, "start the OSC server with serve")
    host: str = setting(
        "127.0.0.1", "other interfaces only by explicit choice", allowed="a host name or IP address", pattern=r"^\S+$"
    )
    port: int = setting(9570, "UDP port; avoids 9000/9001 (VRChat) and 57110/57120 (SuperCollider)", ge=0, le=65535)
    prefix: str = setting(
        "/vibsynth",
        "address prefix of every OSC method",
        allowed=f"an OSC address like /vibsynth (no trailing /), at most {OSC_PREFIX_MAX} characters",
        pattern=r"^(/[A-Za-z0-9_.\-]+)+$",
        max_length=OSC_PREFIX_MAX,
    )
    allow: Annotated[list[str] | None, BeforeValidator(check_allow_list)] = setting(
        [],
        "client addresses allowed (empty = any that can reach the host)",
        allowed="a list of IP addresses, networks or 'localhost', e.g. ['127.0.0.1', '192.168.1.0/24']",
    )
    reply_port: Annotated[int, Field(ge=1, le=65535)] | None = setting(None, "null = reply to the sender's port")
    schedule_horizon_s: float = setting(10.0, "bundles timetagged further ahead are rejected", unit="s", gt=0, le=3600)
    notify_rate_hz: float = setting(30.0, "max pushes per second per subscriber", unit="Hz", gt=0, le=1000)
    tcp: bool = setting(False, "also listen on TCP (SLIP framing) on the same port")
    receive_priority: int = setting(
        1,
        "SCHED_FIFO priority of the UDP receive loop on Linux, kept below JACK's audio threads "
        "(default -P 10); 0 = normally scheduled. Ignored where real-time scheduling is refused or not POSIX",
        ge=0,
        le=9,
    )
    tcp_max_connections: int = setting(64, "open TCP connections in all", ge=1, le=1024)
    tcp_max_per_peer: int = setting(4, "open TCP connections from one client address", ge=1, le=1024)
    tcp_idle_timeout_s: float = setting(
        30.0, "close a TCP connection without a complete packet for this long", unit="s", gt=0, le=86400
    )


class MidiBinding(ValueModel):
    """One MIDI controller bound to a knob: ``{cc: 74}`` or ``{nrpn: [1, 1]}``, optional channel, invert, range."""

    model_config = ConfigDict(json_schema_extra={"oneOf": [{"required": ["cc"]}, {"required": ["nrpn"]}]})

    cc: Annotated[int, Field(ge=0, le=BINDABLE_CC_MAX)] | None = setting(
        None, "controller number (120-127 are channel mode messages, not bindable)"
    )
    nrpn: _Nrpn | None = setting(None, "NRPN parameter number: 0..16383 or [msb, lsb]")
    channel: Annotated[int, Field(ge=1, le=MIDI_CHANNELS)] | None = setting(
        None, "MIDI channel 1-16 (null = every channel)"
    )
    invert: bool = setting(False, "swap the ends")
    range: Annotated[list[float], Field(min_length=2, max_length=2)] | None = setting(
        None, "[low, high] knob values at the controller's ends (null = the knob's live range)"
    )


_Bindings = Annotated[list[MidiBinding], BeforeValidator(check_bindings)]
_BINDINGS_ALLOWED = (
    "a list of bindings like {cc: 74} or {nrpn: [1, 1]} (optional channel 1-16, invert, range [low, high])"
)


class NrpnNumbers(ValueModel):
    """``midi.nrpn``: the NRPN numbers of the two knobs (a knob left out has none)."""

    intensity: _Nrpn | None = setting(None, "NRPN number of intensity")
    balance: _Nrpn | None = setting(None, "NRPN number of balance")


class MidiMapping(Section):
    """``midi.mapping:``: the controllers bound to each knob (MIDI learn writes here)."""

    intensity: _Bindings = setting(
        [{"cc": 11}], "MIDI CC/NRPN bindings of the intensity knob", allowed=_BINDINGS_ALLOWED
    )
    balance: _Bindings = setting(
        [{"cc": 74}, {"cc": 1}], "MIDI CC/NRPN bindings of the balance knob", allowed=_BINDINGS_ALLOWED
    )
    follow_gain: _Bindings = setting(
        [], "bindings of live Follow's gain (range in dB, default [-24, 24])", allowed=_BINDINGS_ALLOWED
    )


class Midi(Section):
    """``midi:``: the MIDI input."""

    enabled: bool = setting(True, "start the MIDI input with serve")
    port: str | Annotated[int, Field(ge=0)] | None = setting(
        None,
        "input name substring or index; null = none unless virtual",
        allowed="a port name substring, an index >= 0, or null",
    )
    virtual: bool = setting(False, 'create a virtual input named "vibsynth"')
    mode: Literal["gate", "continuous"] = setting("gate", "gate | continuous")
    release_ms: float = setting(150.0, "release fade after note-off in gate mode", unit="ms", ge=0, le=GLIDE_MAX_MS)
    velocity_curve: float = setting(1.0, "intensity = (velocity/127) ** curve", ge=0.1, le=10)
    pitch_bend_range: float = setting(0.5, "balance offset at full bend", unit="(knob units)", ge=0, le=8)
    channel_map: Annotated[
        dict[int, Literal["all"] | list[Annotated[int, Field(ge=1)]]], BeforeValidator(check_midi_channel_map)
    ] = setting(
        {1: "all"},
        "MIDI channel (1-16) -> actuator channels (1-based list or 'all')",
        allowed="a mapping {MIDI channel 1-16: 'all' or [actuator channels, 1-based]}",
        schema=_MIDI_CHANNEL_KEYS,
    )
    mpe: bool = setting(False, "MPE: one actuator channel per MIDI channel")
    attack_ms: Annotated[float, Field(ge=0, le=GLIDE_MAX_MS)] | None = setting(
        None, "gate-mode attack glide; null = the knob glide", unit="ms"
    )
    cc_glide_max_ms: float = setting(
        100.0,
        "a CC move glides over the time since that controller's previous move, at most this (no zipper steps)",
        unit="ms",
        ge=0,
        le=GLIDE_MAX_MS,
    )
    reconnect_interval_s: float = setting(
        1.0, "how often a vanished named port is looked for again", unit="s", ge=0.05, le=60
    )
    nrpn: Annotated[NrpnNumbers, BeforeValidator(check_nrpn_map)] = setting(
        {"intensity": [1, 0], "balance": [1, 1]},
        "NRPN numbers of the two knobs, [msb, lsb] (CC 99/98 + data entry 6/38)",
        allowed="a mapping {intensity: [msb, lsb], balance: [msb, lsb]} (or 0..16383)",
    )
    mapping: MidiMapping = Field(default_factory=MidiMapping, description="controllers bound to each knob")


class Speed(Section):
    """``speed:``: OSC ``/speed`` (mm/s) -> texture (docs/osc.md)."""

    curve: Annotated[list[_SpeedPoint], BeforeValidator(SPEED_POINTS.check)] = setting(
        [[0, 0.0], [10, 0.35], [50, 0.6], [150, 0.85], [300, 1.0]],
        "[mm/s, intensity] points, linear between them",
        allowed=SPEED_POINTS.allowed(),
        min_length=SPEED_POINTS.min_points,
    )
    balance_per_decade: float = setting(
        0.0,
        "balance shift per decade of speed above 100 mm/s",
        unit="(knob units per decade)",
        ge=-4,
        le=4,
    )


class Presets(Section):
    """``presets:``: the user's preset folder and hot reload."""

    user_dir: str | None = setting(None, "null = the platform data folder's presets/", allowed="a folder path or null")
    watch: bool = setting(True, "hot reload while serving")


class ChannelPosition(ValueModel):
    """Where one output channel's actuator sits on the body (``layout:``), in metres."""

    x: float = setting(..., "position, left (-) to right (+)", unit="m", ge=-10, le=10)
    y: float = setting(..., "position, back (-) to front (+)", unit="m", ge=-10, le=10)
    z: float = setting(0.0, "position, down (-) to up (+)", unit="m", ge=-10, le=10)
    name: str | None = setting(
        None,
        "a name for the channel (thumb, back-3-2); unique in the layout",
        allowed="lower-case letters and digits in words joined by '-' (e.g. thumb, back-3-2), up to 32 characters",
        pattern=CHANNEL_NAME,
        max_length=32,
    )
    profile: str | None = setting(
        None,
        "this channel's own actuator profile (equalised by a per-channel trim); null = actuator.profile",
        allowed="a profile name (letters, digits, . _ -) or null",
        pattern=PROFILE_NAME,
    )


def check_layout(value: Any) -> Any:
    """A layout: null, a layout name (a string), or a mapping {channel: position} with unique names."""
    if value is None or isinstance(value, str):
        return value
    if not isinstance(value, dict):
        raise problem("must be a layout name or a mapping of positions")
    names: dict[str, Any] = {}
    for channel, position in value.items():
        if isinstance(channel, bool) or not isinstance(channel, int) or not 1 <= channel <= MAX_CHANNELS:
            raise problem(f"key {channel!r} is not an output channel 1..{MAX_CHANNELS}")
        name = position.get("name") if isinstance(position, dict) else None
        if isinstance(name, str):
            if name in names:
                raise problem(f"channel {channel}: name {name!r} is already channel {names[name]}'s", channel)
            names[name] = channel
    return value


def inline_layout_problem(config: VibsynthConfig) -> PydanticCustomError | None:
    """The rule between an inline layout (positions) and ``audio.channels`` broken by ``config``, if any.

    A named layout is checked against its file by the loader (:data:`FILE_CHECKS`), not here.
    """
    value = config.layout
    if not isinstance(value, dict):
        return None
    top = max(value)
    channels = config.audio.channels
    if top > channels:
        return cross_problem(
            f"layout: channel {top} is placed but audio.channels = {channels} (allowed: channels 1..{channels})",
            "layout",
            "audio.channels",
        )
    return None


#: A rule that reads files named by the config (a layout, an actuator profile): the problem, or None.
FileCheck = Callable[["VibsynthConfig"], "PydanticCustomError | None"]
#: Validation context key: the :data:`FileCheck` s to run after the rules between keys. The models
#: read no files; the loader (:mod:`vibsynth.settings.config`) passes the checks of the files it knows.
FILE_CHECKS = "file_checks"


def _layout_kind(value: Any) -> str:
    """Which form a layout has: a name (string) or positions (a mapping); only that form's errors are shown."""
    return "name" if isinstance(value, str) else "positions"


class VibsynthConfig(SettingsModel):
    """The whole configuration file (schema version 1); every key is optional (defaults fill in)."""

    model_config = ConfigDict(title="vibsynth configuration")

    version: int = setting(CONFIG_VERSION, "config schema version", ge=CONFIG_VERSION, le=CONFIG_VERSION)
    audio: Audio = Field(default_factory=Audio, description="the output device and the engine's channels")
    bank: Bank = Field(default_factory=Bank, description="the precomputed noise bank")
    knobs: Knobs = Field(default_factory=Knobs, description="intensity mapping, smoothing, limits, initial state")
    actuator: Actuator = Field(default_factory=Actuator, description="the actuator's frequency response")
    osc: Osc = Field(default_factory=Osc, description="the OSC server")
    midi: Midi = Field(default_factory=Midi, description="the MIDI input")
    midi_clips: MidiClips = Field(default_factory=MidiClips, description="MIDI notes that play haptic clips")
    speed: Speed = Field(default_factory=Speed, description="OSC /speed (mm/s) -> texture")
    presets: Presets = Field(default_factory=Presets, description="user presets and hot reload")
    clips: Clips = Field(default_factory=Clips, description="haptic clips: user folder, hot reload, AHAP/Meta mapping")
    studio: Studio = Field(default_factory=Studio, description="the browser studio served by serve")
    layout: Annotated[
        Annotated[
            Annotated[str, Field(pattern=PROFILE_NAME), Tag("name")]
            | Annotated[dict[int, ChannelPosition], Tag("positions")],
            Discriminator(_layout_kind),
        ]
        | None,
        BeforeValidator(check_layout),
    ] = setting(
        None,
        "where each output channel's actuator is: a layout name (glove, vest-back, wristband) or "
        "{channel: {x, y, z, name}} in metres; null = no layout",
        allowed="null, a layout name, or a mapping {output channel 1..audio.channels: "
        "{x: m, y: m, z: m (default 0), name: text}}",
        schema={"propertyNames": {"pattern": "^[1-9][0-9]*$"}},
    )
    sources: Sources = Field(default_factory=Sources, description="touch sources mixed onto the layout (docs/vr.md)")
    lab: Lab = Field(default_factory=Lab, description="the perception lab: sessions folder, the protocols' defaults")
    follow: Follow = Field(
        default_factory=Follow, description="follow a sound or vibration input live (docs/follow.md)"
    )
    discovery: Discovery = Field(
        default_factory=Discovery, description="OSCQuery and mDNS advertising of the OSC server (docs/osc.md)"
    )
    vrchat: Vrchat = Field(
        default_factory=Vrchat, description="VRChat avatar parameters driving sources, channels, clips (docs/vr.md)"
    )

    @model_validator(mode="after")
    def _cross_check(self, info: ValidationInfo) -> VibsynthConfig:
        """Rules between keys (skipped with context ``{"cross_checks": False}``: one layer at a time)."""
        context = info.context if isinstance(info.context, dict) else {}
        if not context.get("cross_checks", True):
            return self
        audio, bank, knobs = self.audio, self.bank, self.knobs
        if audio.channel_map is not None and len(audio.channel_map) != audio.channels:
            raise cross_problem(
                f"audio.channel_map = {audio.channel_map}: has {len(audio.channel_map)} entries but "
                f"audio.channels = {audio.channels} (allowed: one device output per channel)",
                "audio.channel_map",
                "audio.channels",
            )
        if bank.balance_min >= bank.balance_max:
            raise cross_problem(
                f"bank.balance_max = {bank.balance_max} must be above bank.balance_min = {bank.balance_min}",
                "bank.balance_max",
                "bank.balance_min",
            )
        if knobs.balance_min >= knobs.balance_max:
            raise cross_problem(
                f"knobs.balance_max = {knobs.balance_max} must be above knobs.balance_min = {knobs.balance_min}",
                "knobs.balance_max",
                "knobs.balance_min",
            )
        if knobs.balance_min < bank.balance_min or knobs.balance_max > bank.balance_max:
            raise cross_problem(
                f"live balance range [{knobs.balance_min:g}, {knobs.balance_max:g}] (knobs) must lie within the "
                f"bank's grid [{bank.balance_min:g}, {bank.balance_max:g}] (bank.balance_min/max)",
                "knobs.balance_min",
                "knobs.balance_max",
                "bank.balance_min",
                "bank.balance_max",
            )
        if not knobs.balance_min <= knobs.initial_balance <= knobs.balance_max:
            raise cross_problem(
                f"knobs.initial_balance = {knobs.initial_balance}: outside the live range "
                f"[{knobs.balance_min:g}, {knobs.balance_max:g}] (knobs.balance_min/max)",
                "knobs.initial_balance",
                "knobs.balance_min",
                "knobs.balance_max",
            )
        channels = audio.channels
        for midi_channel, target in self.midi.channel_map.items():
            if isinstance(target, list) and max(target) > channels:
                raise cross_problem(
                    f"midi.channel_map = {self.midi.channel_map}: MIDI channel {midi_channel} targets actuator "
                    f"channel {max(target)} but audio.channels = {channels} (allowed: 1..{channels})",
                    "midi.channel_map",
                    "audio.channels",
                )
        for i, entry in enumerate(self.midi_clips.notes):
            if isinstance(entry.channels, list) and max(entry.channels) > channels:
                raise cross_problem(
                    f"midi_clips.notes[{i}].channels = {entry.channels}: actuator channel {max(entry.channels)} "
                    f"but audio.channels = {channels} (allowed: 1..{channels})",
                    "midi_clips.notes",
                    "audio.channels",
                )
        for i, route in enumerate(self.follow.routes):
            if route.channel is not None and route.channel > channels:
                raise cross_problem(
                    f"follow.routes[{i}].channel = {route.channel}: but audio.channels = {channels} "
                    f"(allowed: 1..{channels})",
                    "follow.routes",
                    "audio.channels",
                )
        for i, param in enumerate(self.vrchat.parameters):
            if param.channel is not None and param.channel > channels:
                raise cross_problem(
                    f"vrchat.parameters[{i}].channel = {param.channel}: but audio.channels = {channels} "
                    f"(allowed: 1..{channels})",
                    "vrchat.parameters",
                    "audio.channels",
                )
            if self.vrchat.enabled and target_of(param) == "source" and self.layout is None:
                raise cross_problem(
                    f"vrchat.parameters[{i}] drives source {param.source}: sources need a layout "
                    "(allowed: set layout, e.g. layout: vest16)",
                    "vrchat.parameters",
                    "layout",
                )
        spatial_error = inline_layout_problem(self) or knob_conflict(self.sources, self.midi.mapping)
        if spatial_error is not None:
            raise spatial_error
        for check in context.get(FILE_CHECKS, ()):
            file_error = check(self)
            if file_error is not None:
                raise file_error
        return self
