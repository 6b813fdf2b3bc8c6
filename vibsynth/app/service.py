"""Wiring for ``vibsynth serve``: config -> basis -> bank -> engine -> output, presets, control adapters.

Flow (one direction, each layer knows only the one below)::

    OSC / MIDI adapters, preset watcher  ->  Controller  ->  Engine.submit
    follow (input ring -> tracker worker) ->  Controller
    output backend (audio thread)        ->  Engine.render_into

:func:`build_engine` and :func:`open_output` are usable on their own (tests,
benchmarks); :func:`serve` runs until Ctrl-C/SIGTERM or ``--seconds``.

A lost audio device does not stop the service: the output's supervisor retries it
with back-off while OSC/MIDI keep working, and ``/status``, the console status line
and the log say ``device lost`` with the reason. SIGTERM/SIGINT exit with code 0
within :data:`EXIT_DEADLINE_S` in every state (see :class:`~vibsynth.engine.supervisor.ExitGuard`).
"""

from __future__ import annotations

import logging
import signal
import sys
import threading
import time
from collections.abc import Callable
from typing import Any

from vibsynth.control import adapter_modules
from vibsynth.control.controller import Controller
from vibsynth.dsp.basis import Basis
from vibsynth.engine.actuator import ActuatorResponse
from vibsynth.engine.bank import BankSpec, load_or_build
from vibsynth.engine.commands import SetMute
from vibsynth.engine.engine import Engine
from vibsynth.engine.outputs import NullOutput, OutputBackend, SoundDeviceOutput, WavOutput
from vibsynth.engine.supervisor import STREAMING, ExitGuard, hard_exit
from vibsynth.engine.trims import ChannelActuator, TrimContext, apply_trims, derive_trims, mean_response
from vibsynth.errors import ConfigError, DeviceError, ParameterError, VibsynthError
from vibsynth.settings.actuators import (
    config_intensity,
    load_actuator_profile,
    profile_intensity,
    resolve_actuator_absolute,
    resolve_actuator_response,
)
from vibsynth.settings.layouts import channel_profile_names
from vibsynth.settings.models_config import Audio, VibsynthConfig

__all__ = [
    "build_engine",
    "open_output",
    "serve",
    "actuator_from_settings",
    "channel_actuators",
    "status_line",
]

log = logging.getLogger(__name__)

#: After SIGTERM/SIGINT, a process run by the CLI exits (code 0) after at most this long,
#: even if closing a device hangs.
EXIT_DEADLINE_S = 1.5


def actuator_from_settings(settings: VibsynthConfig) -> ActuatorResponse:
    """The actuator response to equalise for (explicit points, else the profile, else flat)."""
    actuator = settings.actuator
    return ActuatorResponse.from_points(
        resolve_actuator_response(actuator),
        max_boost_db=actuator.max_boost_db,
        absolute=resolve_actuator_absolute(actuator),
    )


def channel_actuators(settings: VibsynthConfig) -> list[ChannelActuator] | None:
    """Each channel's actuator when some channel has its own profile (else None: one profile for all).

    Channels without their own profile use ``actuator:`` (its points or profile).
    """
    names = channel_profile_names(settings)
    if not any(names):
        return None
    base = ChannelActuator(
        settings.actuator.profile, actuator_from_settings(settings), config_intensity(settings.actuator)
    )
    out = []
    for name in names:
        if name is None:
            out.append(base)
            continue
        profile = load_actuator_profile(name)
        response = ActuatorResponse.from_points(
            profile["response"], max_boost_db=settings.actuator.max_boost_db, absolute=bool(profile["absolute"])
        )
        out.append(ChannelActuator(name, response, profile_intensity(name)))
    return out


def build_engine(
    settings: VibsynthConfig, basis: Basis | None = None, *, progress: Callable[[float, str], None] | None = None
) -> Engine:
    """Build (or load from the cache) the bank and an engine from the typed settings.

    The bank takes ``bank:`` (at ``audio.rate``, equalised for ``actuator:``), the engine
    ``knobs:`` and ``audio:`` (:meth:`Engine.from_settings`). With per-channel profiles
    (``actuator.channel_profiles`` or the layout's), the bank is equalised for the channels'
    mean response and each channel gets its trim (:mod:`vibsynth.engine.trims`).

    Parameters
    ----------
    settings : VibsynthConfig
    basis : Basis, optional
        Default: the shipped basis.
    progress : callable, optional
        ``progress(fraction, message)`` while the bank is built.

    Raises
    ------
    ConfigError
        An invalid bank/knob/audio setting (names the key).
    """
    if basis is None:
        from vibsynth.formats.basis_file import default_basis

        basis = default_basis()
    channels = channel_actuators(settings)
    if channels is None:
        reference, intensity = actuator_from_settings(settings), config_intensity(settings.actuator)
    else:
        reference = mean_response([c.response for c in channels])
        intensity = channels[0].intensity
    try:
        spec = BankSpec.from_settings(settings.bank, settings.audio.rate, reference, intensity)
    except (ParameterError, TypeError, ValueError) as exc:
        raise ConfigError(f"bank/audio settings: {exc}") from None
    cache_dir = settings.bank.cache_dir
    started = time.perf_counter()
    bank, origin = load_or_build(basis, spec, cache_dir=cache_dir, progress=progress)
    log.info(
        "noise bank %s in %.2f s (%d levels x %.1f s at %g Hz)",
        origin,
        time.perf_counter() - started,
        bank.levels,
        bank.n_samples / bank.fs,
        bank.fs,
    )
    try:
        engine = Engine.from_settings(bank, settings.knobs, settings.audio)
    except ParameterError as exc:
        raise ConfigError(f"engine settings: {exc}") from None
    engine.trim_context = TrimContext(basis, reference, intensity, settings.actuator.max_boost_db)
    if channels is not None:
        trims = derive_trims(bank, basis, reference, intensity, channels, max_gain_db=settings.actuator.max_boost_db)
        apply_trims(engine, trims)
        for c, (channel, trim) in enumerate(zip(channels, trims, strict=True)):
            log.info("channel %d (%s): %s", c + 1, channel.name or "actuator.profile", trim.describe())
    return engine


def open_output(
    audio: Audio,
    engine: Engine,
    explicit_device: bool,
    *,
    wav_path: str | None = None,
    seconds: float | None = None,
) -> OutputBackend:
    """Create (and for sounddevice, open) the output of the typed ``audio:`` section.

    ``audio.backend = auto`` tries PortAudio and falls back to :class:`NullOutput`
    with a one-line warning when PortAudio is missing or no device can be opened,
    unless ``explicit_device`` (the user named a device or the sounddevice
    backend): then the :class:`DeviceError` propagates.
    """
    backend = audio.backend
    block = audio.block_size
    if backend == "null":
        return NullOutput(engine, block_size=block or 128)
    if backend == "wav":
        if not wav_path:
            raise ParameterError("the wav output needs a file: -o FILE.wav")
        if seconds is None:
            raise ParameterError("the wav output needs a duration: --seconds N")
        return WavOutput(engine, wav_path, seconds=seconds, block_size=block or 1024)
    output = SoundDeviceOutput(
        engine,
        device=audio.device,
        host_api=audio.host_api,
        block_size=block,
        latency=audio.latency,
        channel_map=None if audio.channel_map is None else list(audio.channel_map),
    )
    try:
        output.open()
    except DeviceError as exc:
        if explicit_device or backend == "sounddevice":
            raise
        log.warning("%s; falling back to the null output (no vibration will be produced)", exc)
        return NullOutput(engine, block_size=block or 128)
    return output


def output_state(output: OutputBackend) -> str:
    """``device lost: JACK server shut down`` (state and reason), or just the state."""
    state, reason = getattr(output, "state", STREAMING), getattr(output, "state_reason", "")
    return f"{state}: {reason}" if reason else str(state)


def status_line(engine: Engine, output: OutputBackend) -> str:
    """One line: output state when not streaming, knobs per channel, underflows, render load."""
    state = output_state(output)
    chans = [] if state == STREAMING else [state]
    for c, (k, b, muted) in enumerate(engine.knob_values()):
        chans.append(f"ch{c + 1} I={k:.2f} B={b:+.2f}{' (muted)' if muted else ''}")
    peak = engine.stats.take_peak()
    return (
        f"{' | '.join(chans)} | underflows {output.stats.underflows} | "
        f"load {100 * engine.stats.load_avg:.1f}% (peak {100 * peak:.0f}%)"
    )


def _load_presets(settings: VibsynthConfig) -> tuple[Any, Any]:
    """(library, PresetWatcher class), or (None, None) when the preset folders cannot be read."""
    from vibsynth.settings.library import load_library
    from vibsynth.settings.reload import PresetWatcher

    try:
        return load_library(settings), PresetWatcher
    except VibsynthError as exc:
        log.warning("presets could not be loaded (%s); serving without them", exc)
        return None, None


def _studio(settings: VibsynthConfig, args: Any, controller: Controller, library: Any, servers: list[Any]) -> Any:
    """Start the studio (after the other adapters: it shows their status); None when disabled."""
    from vibsynth.app.studio_tabs import studio_extensions
    from vibsynth.control.studio import adapter as studio_adapter
    from vibsynth.settings.config_write import user_config_path

    studio = studio_adapter.create(
        settings,
        args,
        controller,
        library,
        servers=list(servers),
        extensions=studio_extensions(
            settings, controller, library, config_path=user_config_path(getattr(args, "config", None))
        ),
    )
    if studio is not None:
        studio.start()
        servers.append(studio)
    return studio


def _follow(settings: VibsynthConfig, controller: Controller, servers: list[Any]) -> None:
    """Start live Follow (``follow:``, ``serve --follow``) when it is on: the input and the follower."""
    if not settings.follow.enabled:
        return  # without importing the follower (scipy.signal: a second of every start)
    from vibsynth.control.follow import service

    follow = service.create(settings, controller)
    if follow is not None:
        follow.start()
        servers.append(follow)


def _oscquery(settings: VibsynthConfig, args: Any, controller: Controller, library: Any, servers: list[Any]) -> Any:
    """Start OSCQuery and mDNS advertising (``discovery:``) for the running OSC server; None when off."""
    from vibsynth.control.oscquery import adapter

    osc = next((s for s in servers if getattr(s, "name", "") == "osc"), None)
    clips = next((s for s in servers if getattr(s, "name", "") == "clips"), None)
    service = adapter.create(settings, args, controller, osc, presets=library, clips=getattr(clips, "library", None))
    if service is not None:
        service.start()
        servers.append(service)
    return service


def _vrchat(settings: VibsynthConfig, args: Any, controller: Controller, servers: list[Any], oscquery: Any) -> None:
    """Start the VRChat bridge (``vrchat:``) on the running OSC server (and its OSCQuery tree) when it is on."""
    from vibsynth.control.vrchat import adapter

    osc = next((s for s in servers if getattr(s, "name", "") == "osc"), None)
    bridge = adapter.create(settings, args, controller, osc, oscquery)
    if bridge is not None:
        bridge.start()
        servers.append(bridge)


def _announce_studio(studio: Any, args: Any, out: Any) -> None:
    """Print the studio's URL line (with its token); ``vibsynth studio`` also opens a browser."""
    from vibsynth.control.studio.adapter import open_in_browser

    print(f"studio: {studio.url}", file=out, flush=True)
    if getattr(args, "open_browser", False):
        # a command opening one tab (vibsynth lab: #lab) names it; the page selects it
        print(f"vibsynth: {open_in_browser(studio.url + getattr(args, 'open_fragment', ''))}", file=out, flush=True)


def serve(settings: VibsynthConfig, args: Any, *, owns_process: bool = False) -> int:
    """Run the service until Ctrl-C/SIGTERM (or ``args.seconds``). Returns the exit code.

    ``args`` attributes used: ``preset``, ``balance``, ``intensity``, ``device``,
    ``output``, ``seconds``, ``wav`` (plus the adapters' own flags).

    Parameters
    ----------
    settings : VibsynthConfig
        The typed settings, built once by the caller (:func:`~vibsynth.settings.config.settings_from_args`);
        each part gets its own sections of it, nothing validates it again.
    owns_process : bool
        True when the service is the process (the CLI): a signal then arms an
        :class:`ExitGuard` (``os._exit(0)`` after :data:`EXIT_DEADLINE_S` if clean-up
        hangs) and PortAudio is shut down at the end without risking a hang in
        sounddevice's exit hook. Library callers and tests leave it False.
    """
    stop = threading.Event()
    guard = ExitGuard(EXIT_DEADLINE_S) if owns_process else None
    previous: dict[signal.Signals, Any] = {}

    def on_signal(signum: int, frame: Any) -> None:  # no logging or locks here
        stop.set()
        if guard is not None:
            guard.arm()

    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGTERM, signal.SIGINT):
            previous[sig] = signal.signal(sig, on_signal)
    try:
        return _serve(settings, args, stop, owns_process)
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


def _serve(settings: VibsynthConfig, args: Any, stop: threading.Event, owns_process: bool) -> int:
    err = sys.stderr
    knobs = settings.knobs
    intensity, balance = getattr(args, "intensity", None), getattr(args, "balance", None)
    # Validate the command line before the (possibly slow) bank build.
    from vibsynth.control.controller import check_range

    if intensity is not None:
        check_range("--intensity", intensity, 0.0, 1.0)
    if balance is not None:
        check_range("--balance", balance, knobs.balance_min, knobs.balance_max)

    def progress(fraction: float, message: str) -> None:
        if err.isatty():
            print(
                f"\rvibsynth: building noise bank: {100 * fraction:3.0f}% {message}\x1b[K", end="", file=err, flush=True
            )

    started = time.perf_counter()
    engine = build_engine(settings, progress=progress)
    if err.isatty():
        print("\r\x1b[K", end="", file=err)
    log.info("engine ready in %.2f s", time.perf_counter() - started)
    if stop.is_set():
        return 0

    library, watcher_cls = _load_presets(settings)
    controller = Controller.for_knobs(engine, knobs, preset_resolver=library.get if library is not None else None)
    for name, value in (("balance", knobs.initial_balance), ("intensity", knobs.initial_intensity)):
        if value:
            controller.set_knob(name, float(value), glide_s=0.0, source="config")
    if getattr(args, "preset", None):
        controller.load_preset(args.preset, source="command line")
    if balance is not None:
        controller.set_knob("balance", balance, glide_s=0.0, source="command line")
    if intensity is not None:
        controller.set_knob("intensity", intensity, glide_s=0.0, source="command line")

    explicit = bool(
        getattr(args, "device", None) is not None
        or getattr(args, "output", None) == "sounddevice"
        or settings.audio.device is not None
    )
    output = open_output(
        settings.audio, engine, explicit, wav_path=getattr(args, "wav", None), seconds=getattr(args, "seconds", None)
    )
    # The control adapters' /status reads output.state / output.state_reason through this.
    controller.output = output  # type: ignore[attr-defined]

    servers: list[Any] = []
    answer_last: list[Any] = []  # bound now (their ports are known), answering once all is up
    watcher = None
    portaudio_clean = True
    try:
        for module in adapter_modules():
            server = module.create(settings, args, controller, library)
            if server is not None:
                if callable(getattr(server, "bind", None)):
                    server.bind()
                    answer_last.append(server)
                else:
                    server.start()
                servers.append(server)
        _follow(settings, controller, servers)
        oscquery = _oscquery(settings, args, controller, library, servers)
        _vrchat(settings, args, controller, servers, oscquery)
        studio = _studio(settings, args, controller, library, servers)
        if library is not None and watcher_cls is not None and settings.presets.watch:
            watcher = watcher_cls(library, on_change=lambda name: controller.reapply_preset(name), interval_s=0.5)
            watcher.start()
        if not stop.is_set():
            output.start()
        # The OSC server answers last: its first /status already lists OSCQuery, Follow, VRChat
        # and the studio (datagrams sent meanwhile wait in its receive buffer, in order).
        for server in answer_last:
            server.start()

        out = sys.stdout
        print(f"vibsynth: serving {engine.channels} channel(s) on {output.describe()}", file=out)
        for server in servers:
            print(f"vibsynth: {server.describe()}", file=out)
        if studio is not None:
            _announce_studio(studio, args, out)
        if oscquery is not None:
            print(f"oscquery: {oscquery.server.url}", file=out, flush=True)
        prefix = settings.osc.prefix.rstrip("/")
        silent = all(k == 0 for k, _, _ in engine.knob_values()) and not intensity
        hint = "silent until a control arrives; " if silent else ""
        print(
            f"vibsynth: {hint}make it vibrate with: vibsynth send {prefix}/intensity 0.5  (Ctrl-C to stop)",
            file=out,
            flush=True,
        )

        deadline = None if getattr(args, "seconds", None) is None else time.monotonic() + float(args.seconds)
        tty = out.isatty()
        next_status = time.monotonic() + 1.0
        while not stop.is_set():
            now = time.monotonic()
            if deadline is not None and now >= deadline:
                break
            if isinstance(output, WavOutput) and not output.is_running():
                break
            if tty and now >= next_status:
                print(f"\r{status_line(engine, output)}\x1b[K", end="", file=out, flush=True)
                next_status += 1.0
            stop.wait(0.05 if deadline is None else max(0.0, min(0.05, deadline - now)))
        if tty:
            print(file=out)
    finally:
        for server in servers:
            try:
                server.stop()
            except Exception as exc:  # keep shutting down
                log.warning("stopping %s: %s", getattr(server, "name", server), exc)
        if watcher is not None:
            watcher.stop()
        if output.is_running() and not isinstance(output, WavOutput):
            # Fade out before closing the device: no click at the end.
            engine.submit(SetMute(True))
            time.sleep(engine.mute_fade_s + 4 * 1024 / engine.fs)
        output.stop()
        if owns_process and isinstance(output, SoundDeviceOutput):
            portaudio_clean = output.shutdown_portaudio()
    log.info("stopped; %d underflow(s)", output.stats.underflows)
    if not portaudio_clean:
        # After a device loss PortAudio/libjack cannot be shut down (their exit-time
        # clean-up would hang or crash): end the process here, code 0.
        log.info("exiting without PortAudio's exit hooks (a device was lost during the run)")
        hard_exit(0)
    return 0
