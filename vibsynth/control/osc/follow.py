"""OSC methods of live Follow: gain, gate, range and focus, per-channel on/off, read back in setter form.

Addresses (docs/osc.md, docs/follow.md "Live")::

    /vibsynth/follow/gain   f dB       (follow.gain_db's range)
    /vibsynth/follow/gate   f dB       (follow.gate_db's range)
    /vibsynth/follow/range  f dB       (follow.range_db's range: the input range spread over the intensity knob)
    /vibsynth/follow/focus  s all|effects|bass|beat
    /vibsynth/follow/get    s gain|gate|range|focus   ->  /vibsynth/follow/gain f  (the setter's form)
    /vibsynth/ch/{n}/follow i 1|0      (off: the channel's knobs take over)
    /vibsynth/ch/{n}/get    s follow   ->  /vibsynth/ch/{n}/follow i

The running follower is :func:`vibsynth.control.follow.follower_of` the controller; without one
(serve started without ``--follow``) every follow message gets an error reply saying so. Bad
values get an error reply naming the range from the typed settings; nothing changes.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from vibsynth.control.controller import Controller
from vibsynth.control.follow import follower_of
from vibsynth.control.osc.codec import Message, encode_message
from vibsynth.control.osc.methods import Getter, Method, arg_count, flag, number, string
from vibsynth.control.osc.workers import PeerLike
from vibsynth.errors import ParameterError, VibsynthError

if TYPE_CHECKING:  # the follower brings the tracker's scipy.signal: every command would import it at start
    from vibsynth.control.follow.follower import Follower

__all__ = ["FollowMethods", "FOLLOW_ADDRESSES", "NOT_RUNNING"]

#: Method -> (OSC type tags, the typed setting giving its range or choices): for discovery (OSCQuery).
FOLLOW_ADDRESSES: dict[str, tuple[str, str]] = {
    "follow/gain": ("f", "follow.gain_db"),
    "follow/gate": ("f", "follow.gate_db"),
    "follow/range": ("f", "follow.range_db"),
    "follow/focus": ("s", "follow.focus"),
    "follow": ("i", "follow.enabled"),
}
#: Names ``/vibsynth/follow/get`` answers.
GET_NAMES = ("gain", "gate", "range", "focus")

NOT_RUNNING = "follow is not running (start serve with --follow DEVICE[:CH,...] or --follow FILE.wav; docs/follow.md)"


class FollowMethods:
    """The follow addresses: a method table (:class:`~vibsynth.control.osc.methods.MethodTable`).

    Parameters
    ----------
    controller : Controller
        Its running follower takes the changes.
    prefix : str
        The server's address prefix (``/vibsynth``), for the answers.
    """

    def __init__(self, controller: Controller, prefix: str) -> None:
        self.controller = controller
        self.prefix = prefix

    def methods(self) -> dict[str, Method]:
        """Method name -> method (``follow`` is per channel: ``/vibsynth/ch/{n}/follow``)."""
        return {
            "follow/gain": self.on_gain,
            "follow/gate": self.on_gate,
            "follow/range": self.on_range,
            "follow/focus": self.on_focus,
            "follow/get": self.on_get,
            "follow": self.on_follow,
        }

    def getters(self) -> dict[str, Getter]:
        """``get follow``: whether each channel follows."""
        return {"follow": self.reply_channels}

    def _follower(self) -> Follower:
        follower = follower_of(self.controller)
        if follower is None:
            raise VibsynthError(NOT_RUNNING)
        return follower

    # ------------------------------------------------------------------ setters
    def on_gain(self, msg: Message, channels: tuple[int, ...] | None, peer: PeerLike, at_frame: int | None) -> None:
        arg_count(msg, (1,), "gain in dB")
        self._follower().set_gain(number(msg, 0, "gain"))

    def on_gate(self, msg: Message, channels: tuple[int, ...] | None, peer: PeerLike, at_frame: int | None) -> None:
        arg_count(msg, (1,), "gate in dB")
        self._follower().set_gate(number(msg, 0, "gate"))

    def on_range(self, msg: Message, channels: tuple[int, ...] | None, peer: PeerLike, at_frame: int | None) -> None:
        arg_count(msg, (1,), "range in dB")
        self._follower().set_range(number(msg, 0, "range"))

    def on_focus(self, msg: Message, channels: tuple[int, ...] | None, peer: PeerLike, at_frame: int | None) -> None:
        arg_count(msg, (1,), "all, effects, bass or beat")
        self._follower().set_focus(string(msg, 0, "focus"))

    def on_follow(self, msg: Message, channels: tuple[int, ...] | None, peer: PeerLike, at_frame: int | None) -> None:
        arg_count(msg, (1,), "1 = follow, 0 = the knobs")
        on = flag(msg, 0, "follow")
        follower = self._follower()
        followed = follower.channels()
        chans = followed if channels is None else channels
        missing = [c + 1 for c in chans if c not in followed]
        if missing:  # refuse the whole message: nothing changes
            names = ", ".join(str(c + 1) for c in followed) or "none"
            raise ParameterError(f"channel {missing[0]} has no follow route (followed channels: {names})")
        for c in chans:
            follower.set_channel(c, on)

    # ------------------------------------------------------------------ queries
    def on_get(self, msg: Message, channels: tuple[int, ...] | None, peer: PeerLike, at_frame: int | None) -> None:
        arg_count(msg, (1,), "gain, gate, range or focus")
        name = string(msg, 0, "setting")
        if name not in GET_NAMES:
            raise ParameterError(f"unknown follow setting {name!r}; known: {', '.join(GET_NAMES)}")
        follower = self._follower()
        address = f"{self.prefix}/follow/{name}"
        if name == "focus":
            peer.send(encode_message(address, (follower.focus,), "s"))
        else:
            peer.send(encode_message(address, (float(getattr(follower, f"{name}_db")),), "f"))

    def reply_channels(self, peer: PeerLike, channels: tuple[int, ...] | None) -> None:
        """Answer ``get follow``: ``/vibsynth/ch/{n}/follow i`` (1 = follows) for each channel asked."""
        follower = self._follower()
        for c in range(self.controller.channels) if channels is None else channels:
            peer.send(encode_message(f"{self.prefix}/ch/{c + 1}/follow", (int(follower.is_on(c)),), "i"))
