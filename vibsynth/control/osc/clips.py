"""OSC methods of haptic clips: ``play`` and ``stop`` on channels, and what plays for ``get`` and ``/status``.

Addresses (docs/clips.md, "Triggering from OSC")::

    /vibsynth/ch/{n}/play  s name [f gain] [f rate] [i loops]    /vibsynth/play ...  (every channel)
    /vibsynth/ch/{n}/stop  [f release_ms]                         /vibsynth/stop ...
    /vibsynth/ch/{n}/get   s "clip"   ->  /vibsynth/ch/{n}/clip s name f position_ms i loops_left

A bundle with a future timetag starts (or stops) the clip at that exact frame. The player is
the controller's running :class:`~vibsynth.control.clips.player.ClipPlayer`
(:func:`vibsynth.control.clips.player_of`); without one, play and stop get an error reply.
"""

from __future__ import annotations

from vibsynth.control.clips import player_of
from vibsynth.control.clips.player import ClipPlayer
from vibsynth.control.clips.status import clip_values
from vibsynth.control.controller import Controller, check_range
from vibsynth.control.osc.codec import Message, encode_message
from vibsynth.control.osc.methods import Getter, Method, arg_count, number, string
from vibsynth.control.osc.workers import PeerLike
from vibsynth.errors import ParameterError, VibsynthError

__all__ = ["SOURCE", "ClipMethods"]

SOURCE = "osc"


class ClipMethods:
    """The clip addresses: a method table (:class:`~vibsynth.control.osc.methods.MethodTable`).

    Parameters
    ----------
    controller : Controller
        Its running clip player plays and stops; its state answers ``get clip``.
    prefix : str
        The server's address prefix (``/vibsynth``), for the ``get clip`` answers.
    """

    def __init__(self, controller: Controller, prefix: str) -> None:
        self.controller = controller
        self.prefix = prefix

    def methods(self) -> dict[str, Method]:
        """Method name -> method, for the handler's table (unknown clips raise ClipError: ``osc.clip``)."""
        return {
            "play": self.on_play,
            "stop": self.on_stop,
            "source/play": self.on_source_play,
            "source/stop": self.on_source_stop,
        }

    def getters(self) -> dict[str, Getter]:
        """``get clip``: what plays on each channel."""
        return {"clip": self.reply_get}

    def _player(self) -> ClipPlayer:
        player = player_of(self.controller)
        if player is None:
            raise VibsynthError("clips are not available (no clip player is running)")
        return player

    @staticmethod
    def _play_args(msg: Message) -> tuple[str, float, float, float]:
        arg_count(msg, (1, 2, 3, 4), "clip name, then optional gain, rate, loops")
        name = string(msg, 0, "clip")
        gain = number(msg, 1, "gain") if len(msg.args) > 1 else 1.0
        rate = number(msg, 2, "rate") if len(msg.args) > 2 else 1.0
        loops = number(msg, 3, "loops") if len(msg.args) > 3 else 1.0
        if len(name) > 128:
            raise ParameterError(f"clip name longer than 128 characters ({len(name)})")
        return name, gain, rate, loops

    def _release_s(self, msg: Message) -> float | None:
        arg_count(msg, (0, 1), "optional release in ms")
        if not msg.args:
            return None
        max_ms = self.controller.limits.glide_max_s * 1000.0
        return check_range("release (ms)", number(msg, 0, "release"), 0.0, max_ms) / 1000.0

    def on_play(self, msg: Message, channels: tuple[int, ...] | None, peer: PeerLike, at_frame: int | None) -> None:
        name, gain, rate, loops = self._play_args(msg)
        self._player().play(
            name, channels=channels, gain=gain, rate=rate, loops=loops, at_frame=at_frame, source=SOURCE
        )

    def on_stop(self, msg: Message, channels: tuple[int, ...] | None, peer: PeerLike, at_frame: int | None) -> None:
        release_s = self._release_s(msg)
        self._player().stop(channels=channels, release_s=release_s, at_frame=at_frame, source=SOURCE)

    def on_source_play(
        self, msg: Message, sources: tuple[int, ...] | None, peer: PeerLike, at_frame: int | None
    ) -> None:
        name, gain, rate, loops = self._play_args(msg)
        self._player().play_source(name, sources=sources, gain=gain, rate=rate, loops=loops, at_frame=at_frame)

    def on_source_stop(
        self, msg: Message, sources: tuple[int, ...] | None, peer: PeerLike, at_frame: int | None
    ) -> None:
        release_s = self._release_s(msg)
        self._player().stop_source(sources=sources, release_s=release_s, at_frame=at_frame)

    # ------------------------------------------------------------------ queries
    def reply_get(self, peer: PeerLike, channels: tuple[int, ...] | None) -> None:
        """Answer ``get clip``: one ``/ch/{n}/clip s f i`` per channel (the global form when all agree)."""
        prefix = self.prefix
        controller = self.controller
        chans = range(controller.channels) if channels is None else channels
        per_channel = {c: clip_values(controller, c) for c in chans}
        if channels is None and len(set(per_channel.values())) == 1:
            peer.send(encode_message(f"{prefix}/clip", per_channel[0], "sfi"))
            return
        for c, vals in per_channel.items():
            peer.send(encode_message(f"{prefix}/ch/{c + 1}/clip", vals, "sfi"))
