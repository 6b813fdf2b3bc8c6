"""``vibsynth calibrate response``: measure an actuator's response through a sensor and write a profile.

The sweep plan (:class:`~vibsynth.dsp.measure.SweepPlan`: a second of silence, then
``--sweeps`` exponential sweeps) is played as one buffer voice of a silent engine on one
output channel, sample-exact (``Engine.play_buffer(at_frame=...)``), while the input ring
records every input of the sensor's device. The two streams' block stamps put the input's
frames on the output's clock (:func:`~vibsynth.engine.input_ring.frame_offset`); what the
loop adds (the actuator, the sensor, the converters) is measured from the impulse
response's peak. The recording is then checked (clipping, a response lost mid-run, a signal
on the chosen input or on another one, background noise, SNR, repeatability) and turned into
an absolute actuator profile (:func:`profile_document`), written atomically only when every
channel of the run passed: a failed run changes no file.
"""

from __future__ import annotations

import datetime as _dt
import logging
import math
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from vibsynth.dsp.measure import Measurement, SweepPlan, measure_recording, response_freqs
from vibsynth.dsp.measure_band import BAND_WITHIN_DB, device_band
from vibsynth.errors import DeviceError, InputError, ParameterError
from vibsynth.settings.models_config import RESPONSE_POINTS

__all__ = [
    "MIN_SNR_DB",
    "MAX_REPEAT_DB",
    "CalibrationResult",
    "check_measurement",
    "profile_document",
    "profile_path",
    "measure_channels",
    "write_profiles",
    "profile_band",
    "apply_iso_curve",
]

log = logging.getLogger(__name__)

#: The lowest SNR (dB) accepted anywhere from 20 to 800 Hz.
MIN_SNR_DB = 20.0
#: The largest disagreement (dB) between sweeps accepted where the SNR is at least MIN_SNR_DB.
MAX_REPEAT_DB = 1.0
#: The response is checked (SNR) over this range, the one the profile is trusted in.
CHECK_BAND_HZ = (20.0, 800.0)
#: A sweep that comes back less than this above the lead silence is no signal (dB, RMS).
MIN_SIGNAL_OVER_FLOOR_DB = 10.0
#: A lead silence above this (dBFS RMS) is background noise, below it a silent input.
NOISE_FLOOR_DBFS = -70.0
#: Points per octave written to a profile (log-frequency interpolation between them).
PROFILE_POINTS_PER_OCTAVE = 12
#: Frames recorded before the expected arrival (the stamps' error) and after the stimulus.
PRE_S = 0.05
MAX_LATENCY_S = 0.45
#: An input whose ring gets no frame for this long has been lost.
INPUT_STALL_S = 1.0


@dataclass(frozen=True)
class CalibrationResult:
    """One channel measured: its measurement and where it came from."""

    channel: int
    measurement: Measurement
    plan: SweepPlan
    output_device: str
    input_device: str
    input_channel: int
    latency_frames: float


def _db(x: float) -> str:
    return f"{x:.1f}"


def _loss_message(m: Measurement, input_label: str) -> str:
    """What :attr:`Measurement.loss` says: when the response stopped, at which frequency of which sweep."""
    loss = m.loss
    assert loss is not None
    n = m.sweeps_db.shape[0]
    if loss.exact:
        when = f"stopped {loss.seconds:.1f} s into sweep {loss.sweep} of {n} (at {loss.freq_hz:.0f} Hz)"
    else:
        when = (
            f"stopped between {loss.seconds:.1f} s into sweep {loss.sweep} (at {loss.freq_hz:.0f} Hz) and "
            f"{loss.missed_seconds:.1f} s into sweep {loss.missed_sweep} (at {loss.missed_freq_hz:.0f} Hz) of {n} "
            "(too weak in between to tell when)"
        )
    return (
        f"the response on {input_label} {when} and did not come back: the input or the actuator was lost "
        "(check the sensor's cable and power, the amplifier and the actuator's wiring, then measure again); "
        "no profile was written"
    )


def check_measurement(
    m: Measurement, *, input_label: str, level_dbfs: float, others: dict[int, Measurement] | None = None
) -> None:
    """Refuse a measurement that cannot be trusted, with one message saying what to change.

    Parameters
    ----------
    m : Measurement
        The chosen input's.
    input_label : str
        ``DEVICE:CH`` for the messages.
    level_dbfs : float
        The sweep's peak level (for the messages).
    others : dict, optional
        1-based input channel -> measurement of the device's other inputs (finds a wrong channel).

    Raises
    ------
    InputError
    """
    if m.clipped:
        raise InputError(
            f"input {input_label} clipped during the sweep ({m.clipped} samples at full scale): lower --level "
            f"(now {level_dbfs:g} dBFS) or the input's gain"
        )
    if m.loss is not None:
        raise InputError(_loss_message(m, input_label))
    lo, hi = CHECK_BAND_HZ
    over = m.signal_rms_db - m.noise_rms_db
    if over < MIN_SIGNAL_OVER_FLOOR_DB:
        for channel, other in sorted((others or {}).items()):
            if other.signal_rms_db - other.noise_rms_db >= MIN_SIGNAL_OVER_FLOOR_DB and other.snr_in(lo, hi) >= 10:
                device = input_label.rpartition(":")[0] or input_label
                raise InputError(
                    f"the sweep came back on input channel {channel}, not on {input_label}: "
                    f"use --input {device}:{channel}"
                )
        if m.noise_rms_db > NOISE_FLOOR_DBFS:
            raise InputError(
                f"background noise on {input_label} ({_db(m.noise_rms_db)} dBFS RMS) is as loud as the sweep came back "
                f"({_db(m.signal_rms_db)} dBFS): quieten the room or the sensor's mounting, or raise --level"
            )
        raise InputError(
            f"no signal on input {input_label} during the sweep ({_db(m.signal_rms_db)} dBFS RMS, silence "
            f"{_db(m.noise_rms_db)} dBFS): is the sensor connected, powered and on this channel, the amplifier on?"
        )
    snr = m.snr_in(lo, hi)
    if snr < MIN_SNR_DB:
        worst = float(
            m.freqs[(m.freqs >= lo) & (m.freqs <= hi)][np.argmin(m.snr_db[(m.freqs >= lo) & (m.freqs <= hi)])]
        )
        raise InputError(
            f"background noise on {input_label} is too close to the sweep: SNR {_db(snr)} dB at {worst:.0f} Hz "
            f"(need {MIN_SNR_DB:g} dB from {lo:g} to {hi:g} Hz; noise {_db(m.noise_rms_db)} dBFS RMS): quieten the "
            "room, raise --level or add --sweeps"
        )
    if m.repeatability_db > MAX_REPEAT_DB:
        raise InputError(
            f"the sweeps on {input_label} disagree by {m.repeatability_db:.1f} dB (need <= {MAX_REPEAT_DB:g}): "
            "something moved or a noise burst hit a sweep; hold the actuator still and measure again"
        )
    sel = (m.freqs >= lo) & (m.freqs <= hi)
    top, bottom = float(np.max(m.response_db[sel])), float(np.min(m.response_db[sel]))
    if top > RESPONSE_POINTS.y_high or bottom < RESPONSE_POINTS.y_low:
        raise InputError(
            f"the response on {input_label} spans {_db(bottom)}..{_db(top)} dB per unit of drive, outside a profile's "
            f"[{RESPONSE_POINTS.y_low:g}, {RESPONSE_POINTS.y_high:g}] dB: change the input's gain"
        )


def _profile_points(m: Measurement) -> list[list[float]]:
    freqs = response_freqs(per_octave=PROFILE_POINTS_PER_OCTAVE)
    db = np.interp(np.log(freqs), np.log(m.freqs), m.response_db)
    lo, hi = RESPONSE_POINTS.y_low, RESPONSE_POINTS.y_high
    return [[round(float(f), 2), round(float(np.clip(v, lo, hi)), 2)] for f, v in zip(freqs, db, strict=True)]


def profile_document(result: CalibrationResult, name: str, *, version: str = "") -> dict[str, Any]:
    """The actuator profile (YAML-ready mapping) of one measured channel.

    ``weighting`` and ``band_hz`` use the model iso-intensity curve
    (:func:`~vibsynth.dsp.measure_band.model_iso_curve_db`) until a lab measures one; the
    provenance says which.
    """
    m = result.measurement
    response = _profile_points(m)
    weighting, band = profile_band(response)
    lo, hi = CHECK_BAND_HZ
    fs = result.plan.fs
    return {
        "name": name,
        "description": f"measured response of output channel {result.channel} through {result.input_device}",
        "example": False,
        "source": "vibsynth calibrate response (exponential sweeps, see docs/calibration.md)",
        "absolute": True,
        "rate": int(round(fs)),
        "response": response,
        "weighting": weighting,
        "band_hz": band,
        "provenance": {
            "date": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
            "vibsynth": version,
            "output_device": result.output_device,
            "output_channel": result.channel,
            "input_device": result.input_device,
            "input_channel": result.input_channel,
            "rate_hz": int(round(fs)),
            "level_dbfs": round(20 * math.log10(result.plan.level), 2),
            "sweeps": int(result.plan.n_sweeps),
            "sweep_hz": [result.plan.f1, result.plan.f2],
            "sweep_s": result.plan.seconds,
            "snr_db_min": round(m.snr_in(lo, hi), 1),
            "snr_db_median": round(float(np.median(m.snr_db[(m.freqs >= lo) & (m.freqs <= hi)])), 1),
            "noise_floor_dbfs": round(m.noise_rms_db, 1),
            "peak_dbfs": round(20 * math.log10(max(m.peak, 1e-12)), 1),
            "latency_ms": round(1000.0 * result.latency_frames / fs, 3),
            "latency_frames": round(result.latency_frames, 2),
            "repeatability_db": round(m.repeatability_db, 3),
            "bands_db": [round(float(v), 2) for v in m.band_db],
            "iso_curve": f"model (docs/calibration.md), band within {BAND_WITHIN_DB:g} dB",
        },
    }


def profile_path(output: str | None, channel: int, *, several: bool, user_dir: Path) -> tuple[str, Path]:
    """(profile name, file) for ``-o``: a name (into the user profile folder) or a ``.yaml`` path.

    With several channels the name gets ``-chN``.
    """
    import re

    from vibsynth.settings.models_config import PROFILE_NAME

    text = output or "measured"
    path = Path(text) if (text.endswith(".yaml") or "/" in text) else user_dir / f"{text}.yaml"
    stem = path.stem + (f"-ch{channel}" if several else "")
    if not re.match(PROFILE_NAME, stem):
        raise ParameterError(f"-o {text!r}: a profile name is letters, digits, '.', '_', '-' (up to 64)")
    return stem, path.with_name(f"{stem}.yaml")


# ---------------------------------------------------------------------- the live run
def _silent_bank(fs: float) -> Any:
    from vibsynth.engine.bank import NoiseBank

    return NoiseBank(
        signals=np.zeros((2, 8192), dtype=np.float32),
        balances=np.array([-1.0, 1.0]),
        peaks=np.ones(2),
        fs=float(fs),
        key={"calibrate": True},
    )


def _input_channels(spec: str, host_api: Any) -> tuple[str, int, int]:
    """(device text, chosen 1-based channel, inputs the device has) of ``DEVICE:CH``."""
    from vibsynth.engine.input_ring import MAX_INPUT_CHANNELS
    from vibsynth.engine.inputs import parse_input_spec
    from vibsynth.engine.outputs import import_sounddevice, resolve_device

    parsed = parse_input_spec(spec)
    if parsed.channels is None or len(parsed.channels) != 1:
        raise ParameterError(f"--input {spec!r}: name one input channel, DEVICE:CH (e.g. system:1)")
    sd = import_sounddevice()
    index = resolve_device(sd, parsed.device, host_api, kind="input")
    available = int(sd.query_devices(index)["max_input_channels"])
    channel = parsed.channels[0]
    if channel > available:
        raise DeviceError(f"--input {spec!r}: the device has {available} inputs (1..{available})")
    device = "" if parsed.device is None else str(parsed.device)
    return device, channel, min(available, MAX_INPUT_CHANNELS)


def _record(
    engine: Any, output: Any, source: Any, stimulus: NDArray[np.float64], channel: int, fs: float
) -> tuple[NDArray[np.float32], float]:
    """Play ``stimulus`` on engine channel ``channel`` (0-based).

    Returns
    -------
    frames : ndarray, shape (n, inputs)
        From :data:`PRE_S` before the stamps' arrival of the first sent sample.
    fraction : float
        Frames from recording index :data:`PRE_S` to the first sent sample's leaving the output
        callback: the arrival's fraction of a frame, less the driver's reported DAC + ADC latency
        (the loop's latency counts them).
    """
    from vibsynth.engine.input_ring import frame_offset, output_stamp
    from vibsynth.engine.supervisor import LOST, RECOVERING

    ring = source.ring
    deadline = time.monotonic() + 5.0
    while output_stamp(engine) is None or ring.stamp() is None:
        if time.monotonic() > deadline:
            raise DeviceError("the output or the input did not start within 5 s")
        time.sleep(0.02)
    ring.skip()
    out_stamp, in_stamp = output_stamp(engine), ring.stamp()
    assert out_stamp is not None and in_stamp is not None
    offset = frame_offset(out_stamp, in_stamp, fs)
    # the whole loop (converters, actuator, sensor) counts from the callbacks' own times
    driver = offset - frame_offset(out_stamp, in_stamp, fs, device_times=False)
    start = engine.frame_position + int(0.3 * fs)
    pre = int(PRE_S * fs)
    first = int(math.floor(start + offset)) - pre  # input frame of recording index 0
    need = stimulus.size + pre + int((MAX_LATENCY_S + 0.1) * fs)
    engine.play_buffer(stimulus, channels=[channel], at_frame=start)
    chunks: list[NDArray[np.float32]] = []
    have_from = ring.frames_read
    got = 0
    last_progress = time.monotonic()
    while True:
        block = ring.read()
        if block.shape[0]:
            last_progress = time.monotonic()
            chunks.append(block)
            got += block.shape[0]
            if have_from + got >= first + need:
                break
        elif time.monotonic() - last_progress > INPUT_STALL_S or source.status().get("state") in ("lost", "retrying"):
            raise InputError(
                f"the input device {source.status().get('device')!r} was lost during the sweep "
                f"({source.status().get('reason') or 'no frames'}); no profile was written"
            )
        else:
            time.sleep(0.02)
        if output.state in (LOST, RECOVERING):
            raise DeviceError(
                f"the output device was lost during the sweep ({output.state_reason}); no profile was written"
            )
    data = np.concatenate(chunks)
    lo = first - have_from
    if lo < 0:
        raise DeviceError("the input started late: its frames before the sweep were not kept; measure again")
    # recording index PRE frames = the stamps' arrival of the first sent sample, less this fraction
    return data[lo : lo + need], (start + offset) - math.floor(start + offset) - driver


def measure_channels(
    settings: Any,
    *,
    channels: list[int],
    input_spec: str,
    level_db: float = -12.0,
    sweeps: int = 3,
    seconds: float = 4.0,
    progress: Callable[[str], None] | None = None,
) -> list[CalibrationResult]:
    """Measure output channels (1-based) one after the other through one input; every check passed.

    ``settings``: the typed settings (its ``audio`` section: device, host API, rate, block,
    latency, channels, channel map).

    Raises
    ------
    InputError, DeviceError, ParameterError
        A check failed (nothing is written by this function in any case).
    """
    from vibsynth.engine.engine import Engine
    from vibsynth.engine.inputs import SoundDeviceInput
    from vibsynth.engine.outputs import SoundDeviceOutput

    audio = settings.audio
    fs = float(audio.rate)
    if not (math.isfinite(level_db) and -60.0 <= level_db <= 0.0):
        raise ParameterError(f"--level must be in [-60, 0] dBFS, got {level_db!r}")
    for c in channels:
        if not 1 <= c <= audio.channels:
            raise ParameterError(f"--channel {c}: the engine has channels 1..{audio.channels} (audio.channels)")
    plan = SweepPlan(fs=fs, f2=min(2000.0, 0.45 * fs), seconds=seconds, n_sweeps=sweeps, level=10 ** (level_db / 20))
    device, in_channel, n_inputs = _input_channels(input_spec, audio.host_api)
    label = f"{device or 'default'}:{in_channel}"
    engine = Engine(_silent_bank(fs), channels=audio.channels, max_block=min(audio.block_size, 4096))
    output = SoundDeviceOutput(
        engine,
        device=audio.device,
        host_api=audio.host_api,
        block_size=audio.block_size,
        latency=audio.latency,
        channel_map=audio.channel_map,
    )
    all_inputs = f"{device}:{','.join(str(c) for c in range(1, n_inputs + 1))}"
    source = SoundDeviceInput(all_inputs, fs=fs, host_api=audio.host_api, block_size=audio.block_size, seconds=4.0)
    results: list[CalibrationResult] = []
    failure: BaseException | None = None
    try:
        output.start()
        source.open()
        stimulus = plan.stimulus()
        for c in channels:
            if progress:
                progress(f"channel {c}: {sweeps} sweeps of {seconds:g} s at {level_db:g} dBFS")
            data, fraction = _record(engine, output, source, stimulus, c - 1, fs)
            pre = int(PRE_S * fs)
            chosen = measure_recording(
                data[:, in_channel - 1].astype(np.float64), plan, min_snr_db=MIN_SNR_DB, max_latency_s=MAX_LATENCY_S
            )
            others: dict[int, Measurement] = {}
            quick = SweepPlan(fs=fs, f1=plan.f1, f2=plan.f2, seconds=seconds, n_sweeps=1, level=plan.level)
            if chosen.signal_rms_db - chosen.noise_rms_db < MIN_SIGNAL_OVER_FLOOR_DB:
                for k in range(1, n_inputs + 1):
                    if k != in_channel:
                        others[k] = measure_recording(
                            data[:, k - 1].astype(np.float64), quick, max_latency_s=MAX_LATENCY_S
                        )
            in_label = f"{source.status().get('device') or label}:{in_channel}" if device == "" else label
            check_measurement(chosen, input_label=in_label, level_dbfs=level_db, others=others)
            results.append(
                CalibrationResult(
                    channel=c,
                    measurement=chosen,
                    plan=plan,
                    output_device=output._device_label(),
                    input_device=str(source.status().get("device") or label),
                    input_channel=in_channel,
                    latency_frames=chosen.latency - pre - fraction,
                )
            )
    except BaseException as exc:
        failure = exc
        raise
    finally:
        source.close()
        output.stop()
        if not output.shutdown_portaudio():
            # After a device loss PortAudio/libjack cannot be shut down (their exit-time clean-up
            # would hang): say what failed as the command line does and end the process here.
            from vibsynth.engine.supervisor import hard_exit

            reason = (
                failure if failure is not None else "the audio device was lost at the end of the run; measure again"
            )
            print(f"vibsynth: error: {reason}", file=sys.stderr)
            hard_exit(1)
    return results


def write_profiles(
    results: list[CalibrationResult], output: str | None, *, user_dir: Path, version: str = ""
) -> list[Path]:
    """Write one profile per measured channel (atomically, only after all were measured)."""
    from vibsynth.formats.files import atomic_write
    from vibsynth.formats.yamlio import dump_yaml

    several = len(results) > 1
    docs = []
    for r in results:
        name, path = profile_path(output, r.channel, several=several, user_dir=user_dir)
        docs.append((path, profile_document(r, name, version=version)))
    written = []
    for path, doc in docs:
        path.parent.mkdir(parents=True, exist_ok=True)
        header = "# Measured by vibsynth calibrate response: absolute (recorded level per unit of drive).\n"
        atomic_write(path, header + dump_yaml(doc, sort_keys=False, width=120))
        written.append(path)
    return written


# ---------------------------------------------------------------------- iso-intensity curves
def profile_band(
    response: list[list[float]],
    iso_freqs: Any = None,
    iso_db: Any = None,
    *,
    within_db: float = BAND_WITHIN_DB,
) -> tuple[list[list[float]], list[float]]:
    """A profile's ``weighting`` points and ``band_hz`` from its ``response`` points and an iso-intensity curve.

    Parameters
    ----------
    response : list of [Hz, dB]
        The profile's response.
    iso_freqs, iso_db : array_like, shape (k,), optional
        The acceleration felt as equally intense at ``iso_freqs`` Hz (dB, any reference; a lab's
        iso-intensity sines); None = the model curve.
    within_db : float

    Returns
    -------
    weighting : list of [Hz, dB]
        On the profile grid, clipped to the profile's dB range.
    band_hz : [low, high]
    """
    pts = np.asarray(response, dtype=np.float64)
    freqs = response_freqs()
    r = np.interp(np.log(freqs), np.log(pts[:, 0]), pts[:, 1])
    weighting, band = device_band(freqs, r, iso_freqs, iso_db, within_db=within_db)
    wf = response_freqs(per_octave=PROFILE_POINTS_PER_OCTAVE)
    wdb = np.clip(np.interp(np.log(wf), np.log(freqs), weighting), RESPONSE_POINTS.y_low, 0.0)
    points = [[round(float(f), 2), round(float(v), 2)] for f, v in zip(wf, wdb, strict=True)]
    return points, [round(band[0], 1), round(band[1], 1)]


def apply_iso_curve(path: str | Path, iso_freqs: Any, iso_db: Any, *, source: str) -> dict[str, Any]:
    """Re-derive a profile file's weighting and band from a measured iso-intensity curve; write it atomically.

    For the lab's iso-intensity protocol and the studio's "apply to channel": the response is
    kept, ``weighting``, ``band_hz`` and ``provenance.iso_curve`` (``source``, e.g. the lab
    session) change.

    Returns
    -------
    profile : dict
        What was written.

    Raises
    ------
    ConfigError
        The file is no valid profile (nothing is written).
    ParameterError
        The curve is malformed.
    """
    from vibsynth.formats.files import atomic_write
    from vibsynth.formats.yamlio import dump_yaml
    from vibsynth.settings.actuators import read_actuator_profile

    target = Path(path)
    model = read_actuator_profile(target)
    doc = model.model_dump(exclude_none=True)
    doc["weighting"], doc["band_hz"] = profile_band([list(p) for p in model.response], iso_freqs, iso_db)
    provenance = dict(doc.get("provenance") or {})
    provenance["iso_curve"] = f"{source}, band within {BAND_WITHIN_DB:g} dB"
    doc["provenance"] = provenance
    read_back = {"name": target.stem, **{k: v for k, v in doc.items() if k != "name"}}
    atomic_write(target, dump_yaml(read_back, sort_keys=False, width=120))
    return read_back
