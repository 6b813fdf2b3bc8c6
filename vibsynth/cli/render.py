"""``vibsynth render``: a texture (or a recording's paper variant, or a MIDI performance) to a WAV file."""

from __future__ import annotations

import argparse
import logging
import math
import sys

import numpy as np

from vibsynth.app.render import LoopSource, RenderResult, Sink, loop_period, render
from vibsynth.cli._clip_play import add_clip_play_arguments
from vibsynth.cli._common import (
    add_basis_argument,
    basis_from_args,
    finite_float,
    integer_in,
    positive_seconds,
    sample_rate,
    unit_interval,
)
from vibsynth.cli._follow import add_follow_options, run_follow_render
from vibsynth.cli._inputs import wav_channel
from vibsynth.cli._progress import RenderProgress, add_quiet_argument
from vibsynth.cli.analyze import analyze_file
from vibsynth.dsp.analysis import VARIANTS, variant_spectra
from vibsynth.dsp.basis import Basis
from vibsynth.dsp.intensity import DEFAULT_CEILING_DB, DEFAULT_RANGE_DB, knob_to_level_db
from vibsynth.dsp.synthesis import SpectralShaper
from vibsynth.errors import InputError, ParameterError
from vibsynth.formats.wav_stream import WavStreamWriter, check_target

ORDER = 20

#: Longest period synthesised in one piece (8 s at 48 kHz): a longer render repeats a
#: period of 1/2 to 1 times this (a divisor of its length, so it still loops seamlessly),
#: which bounds the synthesis' memory (~17 MB per second of period at 48 kHz).
MAX_PERIOD_FRAMES = 384_000
#: Frames per block when streaming a period to the file.
LOOP_BLOCK = 65_536
#: A rendered balance further than this (knob units) from the one asked for is reported
#: as saturated (the closed-form synthesis reaches the asked balance to ~1e-6 elsewhere).
BALANCE_SATURATION_TOLERANCE = 0.01

log = logging.getLogger(__name__)

HELP = """\
Render noise with the paper's spectrum model (a texture loops seamlessly) to a WAV file:
  --balance B --intensity I   the spectrum M + t1(B) V1 at intensity knob I (0..1; see --ceiling-db)
  --from FILE --variant V     a recording's experiment-3 variant at the recording's own level:
                              S1 = M + t1 V1, S1:8 = all 8 components, S2:8 = all but the first, M = mean
  --midi FILE.mid             a MIDI performance through the live MIDI mapping and the real-time engine
  --clip NAME|FILE.yaml       a haptic clip (vibsynth clip list, or a clip file) through the real-time
                              engine, as /vibsynth/play plays it (--gain, --clip-rate, --loops; docs/clips.md)
  --follow IN.wav|FOLDER      the haptic track Follow makes of a sound or vibration recording, aligned
                              to it, streamed (--follow-mode, --follow-focus; docs/follow.md); a folder
                              renders every WAV under it into -o FOLDER, --jobs at a time or on --dask
The band powers of the result match the target within rounding (closed-form synthesis).
The output is written as it renders: memory stays flat whatever --seconds. A texture longer
than 8 s (at 48 kHz; 384,000 samples) repeats one seamless period of 4-8 s.
A balance beyond what the basis can reach (about -5.4..+2.8 on the default one) is
rendered at the edge, with a warning. A progress bar shows on a terminal (not with -q).
Exit codes: 2 for a bad argument, 1 for a file that cannot be read or written.
"""


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "render",
        help="render a texture to a WAV file",
        description=HELP,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    source = p.add_mutually_exclusive_group(required=True)
    source.add_argument("--balance", type=finite_float, metavar="B", help="high/low balance (knob units)")
    source.add_argument("--from", dest="from_file", metavar="FILE", help="recording to re-synthesize")
    source.add_argument("--midi", metavar="FILE.mid", help="MIDI file to render through the MIDI mapping")
    source.add_argument(
        "--clip", metavar="NAME|FILE.yaml", help="haptic clip to render (see vibsynth clip list), or a clip file"
    )
    source.add_argument(
        "--follow",
        metavar="IN.wav|FOLDER",
        help="render the haptic track of a sound file (WAV, FLAC, Ogg, MP3...) or a folder of them (Follow, offline)",
    )
    p.add_argument("--intensity", type=unit_interval, metavar="I", help="intensity knob 0..1 (with --balance)")
    p.add_argument(
        "--channel",
        type=wav_channel,
        default=0,
        metavar="N",
        help="channel of a multi-channel WAV, 1 = the first (with --from)",
    )
    p.add_argument("--variant", choices=list(VARIANTS), default="S1", help="variant (with --from; default S1)")
    p.add_argument("--seconds", type=positive_seconds, default=None, metavar="S", help="duration (default 4 s)")
    p.add_argument(
        "--rate",
        type=sample_rate,
        default=None,
        metavar="HZ",
        help="output rate (default 48000; with --from, the recording's rate; also the rate of CSV/TXT input)",
    )
    p.add_argument("-o", "--output", required=True, metavar="OUT.wav", help="WAV file to write")
    p.add_argument("--format", choices=("float32", "pcm16"), default="float32", help="WAV sample format")
    p.add_argument(
        "--seed", type=integer_in(0, what="seed"), default=None, help="random phases, an integer >= 0 (default: fresh)"
    )
    p.add_argument("--ceiling-db", type=finite_float, default=DEFAULT_CEILING_DB, help="intensity knob ceiling (dB)")
    p.add_argument("--range-db", type=finite_float, default=DEFAULT_RANGE_DB, help="intensity knob range (dB)")
    p.add_argument("--config", metavar="FILE", help="config file (with --midi or --clip)")
    add_clip_play_arguments(p)
    add_follow_options(p, prefix="follow-", force=False)
    add_quiet_argument(p)
    add_basis_argument(p)
    p.set_defaults(func=run)


def _render_midi(args: argparse.Namespace) -> RenderResult:
    from vibsynth.app.midi_render import prepare_midi_render, render_midi_to
    from vibsynth.settings.config import load_config

    overrides = {"audio": {"rate": int(args.rate)}} if args.rate else None
    settings = load_config(args.config, overrides=overrides).settings
    from vibsynth.settings.library import load_library

    presets = load_library(settings)
    job = prepare_midi_render(
        args.midi, settings=settings, basis=basis_from_args(args), seconds=args.seconds, presets=presets
    )
    with (
        _writer(args, job.fs, job.engine.channels, job.frames) as wav,
        RenderProgress("render", job.frames, job.fs, quiet=args.quiet) as progress,
    ):
        return render_midi_to(job, _FullScaleGuard(wav, args.format), progress=progress)


def _render_clip(args: argparse.Namespace) -> RenderResult:
    """A haptic clip through the engine, compiled as the live player compiles it."""
    from vibsynth.app.clip_render import prepare_clip_render
    from vibsynth.cli.clip import clip_by_name_or_path
    from vibsynth.settings.clips import load_clip_library
    from vibsynth.settings.config import load_config

    overrides = {"audio": {"rate": int(args.rate)}} if args.rate else None
    settings = load_config(args.config, overrides=overrides).settings
    clip = clip_by_name_or_path(load_clip_library(settings), args.clip)
    job = prepare_clip_render(
        clip,
        settings=settings,
        basis=basis_from_args(args),
        gain=args.gain,
        rate=args.clip_rate,
        loops=args.loops,
        seconds=args.seconds,
    )
    with (
        _writer(args, job.fs, job.engine.channels, job.frames) as wav,
        RenderProgress("render", job.frames, job.fs, quiet=args.quiet) as progress,
    ):
        return render(
            job.engine, job.frames, _FullScaleGuard(wav, args.format), timeline=job.timeline, progress=progress
        )


def _render_loop(args: argparse.Namespace) -> RenderResult:
    """A texture or a recording's variant: one period of the closed-form synthesis, repeated."""
    basis = basis_from_args(args)
    seconds = args.seconds or 4.0
    rng = np.random.default_rng(args.seed)
    if args.balance is not None:
        if args.intensity is None:
            raise ParameterError("--balance needs --intensity I (0..1)")
        if args.intensity == 0.0:
            raise ParameterError("--intensity 0 is silence; nothing to render")
        analysis = None
        fs = args.rate or 48000.0
    else:
        analysis = analyze_file(args.from_file, args, basis)
        fs = args.rate or analysis.fs
    frames = int(round(seconds * fs))
    period = loop_period(frames, MAX_PERIOD_FRAMES)
    shaper = SpectralShaper(fs=fs, n_samples=period, centres=basis.centres_hz, order=basis.filter_order)
    if analysis is None:
        level = knob_to_level_db(args.intensity, ceiling_db=args.ceiling_db, range_db=args.range_db)
        weights = shaper.solve_balance(basis, args.balance, level_db=level)
        _warn_if_saturated(shaper, basis, weights, args)
    else:
        weights = shaper.solve_weights(variant_spectra(analysis, basis)[args.variant], level_db=analysis.level_db)
    source = LoopSource(shaper.render(shaper.power_envelope(weights), shaper.random_phases(rng)), fs)
    _check_full_scale(source.peak, args.format)
    with (
        _writer(args, fs, 1, frames) as wav,
        RenderProgress("render", frames, fs, quiet=args.quiet) as progress,
    ):
        return render(source, frames, wav, block=LOOP_BLOCK, progress=progress)


def reachable_balance(shaper: SpectralShaper, basis: Basis) -> tuple[float, float]:
    """The lowest and highest balance (knob units) the closed-form synthesis can render on ``basis``.

    Beyond them the *measured* balance saturates (``SpectralShaper.solve_balance``: the
    filter bank's adjacent-band leakage caps the slopes a signal can show). The range
    does not depend on the level (the shape is solved first, then scaled), so it holds
    at every intensity.

    Parameters
    ----------
    shaper : SpectralShaper
    basis : Basis

    Returns
    -------
    (low, high) : tuple of float
    """
    (_, low_t1), (_, high_t1) = shaper.reachable_t1(basis)
    return float(basis.balance_from_t1(low_t1)), float(basis.balance_from_t1(high_t1))


def _warn_if_saturated(shaper: SpectralShaper, basis: Basis, weights: np.ndarray, args: argparse.Namespace) -> None:
    """One warning line when the rendered balance falls short of ``--balance`` (it saturated)."""
    rendered = float(basis.balance_from_t1(basis.scores(shaper.weights_band_db(weights))[0]))
    if abs(rendered - args.balance) <= BALANCE_SATURATION_TOLERANCE:
        return
    low, high = reachable_balance(shaper, basis)
    print(
        f"vibsynth: warning: balance {args.balance:g} is beyond what basis {basis.id} can render "
        f"(reachable: {low:+.2f} .. {high:+.2f}, at intensity {args.intensity:g} as at any); "
        f"rendered at {rendered:+.2f}",
        file=sys.stderr,
    )


def run(args: argparse.Namespace) -> int:
    """Exit 0; 1 (one line) when a file cannot be read or written; bad arguments raise (exit 2)."""
    if not args.clip and (args.gain, args.clip_rate, args.loops) != (1.0, 1.0, 1):
        raise ParameterError("--gain, --clip-rate and --loops go with --clip NAME")
    if args.follow:
        from vibsynth.settings.config import load_config

        if args.seconds is not None:
            raise ParameterError("render --follow renders the input's own length; --seconds does not apply")

        overrides = {"audio": {"rate": int(args.rate)}} if args.rate else None
        return run_follow_render(args, load_config(args.config, overrides=overrides).settings)
    if (args.follow_mode, args.follow_focus, args.jobs, args.dask) != ("vibration", "all", None, None):
        raise ParameterError("--follow-mode, --follow-focus, --jobs and --dask go with --follow IN.wav|FOLDER")
    try:
        check_target(args.output, writable=True)
        result = _render_midi(args) if args.midi else _render_clip(args) if args.clip else _render_loop(args)
    except OSError as exc:  # the output file: missing folder, a folder, no permission, disk full
        where = exc.filename if exc.filename is not None else args.output
        print(f"vibsynth: error: {where}: {exc.strerror or exc}", file=sys.stderr)
        return 1
    except InputError as exc:  # an input file (recording, MIDI file, basis) that cannot be used
        print(f"vibsynth: error: {exc}", file=sys.stderr)
        return 1
    peak = result.peak
    if peak >= 1.0:  # float32 only: pcm16 refuses before anything is written
        print(f"vibsynth: warning: {_full_scale_message(peak)}; float32 WAV keeps it unclipped", file=sys.stderr)
    db = 20 * math.log10(peak) if peak > 0 else -math.inf
    if not args.quiet:
        print(f"wrote {args.output}: {result.seconds:.2f} s at {result.fs:g} Hz, peak {db:.1f} dBFS")
    return 0


def _writer(args: argparse.Namespace, fs: float, channels: int, frames: int) -> WavStreamWriter:
    return WavStreamWriter(args.output, fs, channels, sample_format=args.format, frames=frames)


def _full_scale_message(peak: float) -> str:
    return f"peak {peak:.2f} exceeds full scale (lower --intensity or --ceiling-db)"


def _check_full_scale(peak: float, sample_format: str) -> None:
    if peak >= 1.0 and sample_format == "pcm16":
        raise ParameterError(_full_scale_message(peak) + "; pcm16 would clip")


class _FullScaleGuard:
    """Refuse a pcm16 render that reaches full scale (the file is then discarded)."""

    def __init__(self, sink: Sink, sample_format: str) -> None:
        self.sink, self.sample_format = sink, sample_format

    def write(self, block: np.ndarray) -> None:
        if self.sample_format == "pcm16" and block.size:
            _check_full_scale(float(np.max(np.abs(block))), self.sample_format)
        self.sink.write(block)

    def close(self) -> object:
        return self.sink.close()

    def abort(self) -> None:
        self.sink.abort()
