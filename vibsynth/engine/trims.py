"""Per-channel actuator profiles in playback: one shared bank, one trim per channel.

The 37 MB noise bank is shared by every channel, so it is pre-equalised for one reference
response ``R_0``; each channel whose actuator has its own response ``R_c`` gets a trim (a gain
curve over the bank's levels and a balance offset, :meth:`Engine.set_trim
<vibsynth.engine.engine.Engine.set_trim>`) derived by :func:`vibsynth.dsp.channel_trim.channel_trim`
from ``d = R_c - R_0``.

The reference is the **mean** (dB, at every frequency) of the channels' responses rather than
any one of them: what a trim cannot equalise is the part of ``d`` that is neither a level nor a
V1 tilt, and the mean makes the sum of those residuals over the channels smallest, and keeps
the trims' gains centred on 0 dB (least boost, least limiter). With one response for every
channel the mean is that response and every trim is the identity.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from vibsynth.dsp.basis import Basis
from vibsynth.dsp.channel_trim import ChannelTrim, channel_trim
from vibsynth.dsp.felt_intensity import PAPER_WEIGHTING, IntensityWeighting
from vibsynth.engine.actuator import ActuatorResponse
from vibsynth.engine.bank import NoiseBank, felt_spectra
from vibsynth.engine.engine import Engine
from vibsynth.errors import ConfigError, ParameterError

__all__ = ["ChannelActuator", "TrimContext", "mean_response", "derive_trims", "apply_trims", "retrim_channel"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class ChannelActuator:
    """One output channel's actuator.

    Attributes
    ----------
    name : str or None
        Its profile's name (None: ``actuator.profile`` or explicit points).
    response : ActuatorResponse
    intensity : IntensityWeighting
        The profile's calibrated weighting (the paper's band without one).
    """

    name: str | None
    response: ActuatorResponse
    intensity: IntensityWeighting = PAPER_WEIGHTING


@dataclass(frozen=True)
class TrimContext:
    """What a running engine's bank was built for: enough to trim a channel for another actuator later.

    Attributes
    ----------
    basis : Basis
    reference : ActuatorResponse
        The response the bank was equalised for.
    intensity : IntensityWeighting
        The weighting it was normalised with.
    max_gain_db : float
        ``actuator.max_boost_db``.
    """

    basis: Basis
    reference: ActuatorResponse
    intensity: IntensityWeighting
    max_gain_db: float


def mean_response(responses: Sequence[ActuatorResponse]) -> ActuatorResponse:
    """The mean (dB) of responses, on the union of their points (exact for log-linear interpolation).

    Parameters
    ----------
    responses : sequence of ActuatorResponse
        Same ``absolute`` flag and boost limit (the first's are kept).

    Returns
    -------
    mean : ActuatorResponse
        The first one itself when they are all equal.
    """
    if not responses:
        raise ParameterError("mean_response needs at least one response")
    first = responses[0]
    if all(r.points == first.points for r in responses):
        return first
    freqs = np.unique(np.concatenate([[p[0] for p in r.points] for r in responses if r.points]))
    mean = np.mean([r.response_db(freqs) for r in responses], axis=0)
    return ActuatorResponse.from_points(
        [(float(f), float(db)) for f, db in zip(freqs, mean, strict=True)],
        max_boost_db=first.max_boost_db,
        absolute=first.absolute,
    )


def derive_trims(
    bank: NoiseBank,
    basis: Basis,
    reference: ActuatorResponse,
    intensity: IntensityWeighting,
    channels: Sequence[ChannelActuator],
    *,
    max_gain_db: float,
) -> list[ChannelTrim]:
    """Each channel's trim against a bank built for ``reference`` under ``intensity``.

    Parameters
    ----------
    bank : NoiseBank
    basis : Basis
        The basis the bank was built from.
    reference : ActuatorResponse
        The response the bank was equalised for.
    intensity : IntensityWeighting
        The weighting the bank was normalised with.
    channels : sequence of ChannelActuator
        One per engine channel.
    max_gain_db : float
        ``actuator.max_boost_db``.

    Returns
    -------
    trims : list of ChannelTrim
        One per channel (the identity where the channel's response is the reference's).
    """
    trims: list[ChannelTrim] = []
    spectra = None
    for channel in channels:
        same_weighting = channel.intensity == intensity
        if channel.response.points == reference.points and same_weighting:
            trims.append(ChannelTrim())
            continue
        if spectra is None:
            spectra = felt_spectra(bank, reference)
        freqs, power = spectra
        delta = channel.response.response_db(freqs) - reference.response_db(freqs)
        try:
            trims.append(
                channel_trim(
                    basis,
                    freqs,
                    power,
                    bank.balances,
                    delta,
                    weighting=intensity,
                    channel_weighting=channel.intensity,
                    max_gain_db=max_gain_db,
                )
            )
        except ParameterError as exc:
            raise ConfigError(f"actuator profile {channel.name or '(actuator.profile)'}: {exc}") from None
    return trims


def retrim_channel(engine: Engine, context: TrimContext, channel: int, actuator: ChannelActuator) -> ChannelTrim:
    """Trim one channel of a running engine for ``actuator`` (glided in over 50 ms).

    Parameters
    ----------
    engine : Engine
    context : TrimContext
        What the engine's bank was built for.
    channel : int
        0-based.
    actuator : ChannelActuator

    Raises
    ------
    ConfigError
        A measured (absolute) response against a bank built for a relative one, or the reverse.
    """
    if actuator.response.absolute != context.reference.absolute:
        kinds = ("relative", "measured (absolute)")
        raise ConfigError(
            f"profile {actuator.name} is {kinds[actuator.response.absolute]} but the engine's bank was built for a "
            f"{kinds[context.reference.absolute]} response: their responses cannot be compared"
        )
    (trim,) = derive_trims(
        engine.bank, context.basis, context.reference, context.intensity, [actuator], max_gain_db=context.max_gain_db
    )
    engine.set_trim(trim.gains(engine.bank.levels), trim.balance_offset, channels=[channel])
    return trim


def apply_trims(engine: Engine, trims: Sequence[ChannelTrim], *, glide_s: float = 0.0) -> None:
    """Send each channel's trim to the engine (channel ``c`` gets ``trims[c]``)."""
    for c, trim in enumerate(trims):
        engine.set_trim(trim.gains(engine.bank.levels), trim.balance_offset, channels=[c], glide_s=glide_s)
