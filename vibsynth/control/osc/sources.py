"""OSC methods of the touch sources: ``/vibsynth/source/{k}/...`` (k = 1..16; docs/osc.md, docs/vr.md).

Each method validates its arguments at the edge (an error reply names the problem and
nothing changes), then hands the change to the running
:class:`~vibsynth.control.spatial.mixer.SourceMixer`, now or at the bundle's stream frame.
A pattern address reaching several sources (``/vibsynth/source/*/on 0``) changes them
together. Without a layout there is no mixer: every source message gets an error reply
saying so.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

from vibsynth.control import spatial
from vibsynth.control.controller import Controller
from vibsynth.control.osc.codec import Message, encode_message
from vibsynth.control.osc.methods import Getter, Method, arg_count, flag, number, string
from vibsynth.control.osc.workers import PeerLike
from vibsynth.control.spatial.mixer import SourceMixer, Update
from vibsynth.control.spatial.sources import SETTING_NAMES, SourceTable, SourceView
from vibsynth.dsp.spatial import check_rolloff
from vibsynth.errors import ParameterError, VibsynthError

__all__ = ["SourceMethods", "NO_LAYOUT"]

#: The error of a source message on a server without a layout.
NO_LAYOUT = (
    "sources need a layout: name one in the config (layout: glove, vest-back, wristband, or positions; "
    "see docs/vr.md) and restart the server"
)


class SourceMethods:
    """The source methods: a method table (:class:`~vibsynth.control.osc.methods.MethodTable`).

    Parameters
    ----------
    controller : Controller
        Its running mixer (:func:`vibsynth.control.spatial.mixer_of`) takes the changes.
    prefix : str
        The server's address prefix (``/vibsynth``), for the ``get`` answers.
    """

    def __init__(self, controller: Controller, prefix: str) -> None:
        self.prefix = prefix
        self.controller = controller

    def methods(self) -> dict[str, Method]:
        """``source/<method>`` -> the function the handler calls with the 0-based source indices."""
        return {
            "source/pos": self._on_pos,
            "source/texture": self._on_texture,
            "source/intensity": self._on_intensity,
            "source/balance": self._on_balance,
            "source/preset": self._on_preset,
            "source/radius": self._on_radius,
            "source/rolloff": self._on_rolloff,
            "source/on": self._on_on,
            "source/speed": self._on_speed,
            "source/get": self._on_get,
        }

    def getters(self) -> dict[str, Getter]:
        """None: a source's settings are read with ``/vibsynth/source/{k}/get`` (a method above)."""
        return {}

    # ------------------------------------------------------------------ helpers
    def _mixer(self) -> SourceMixer:
        mixer = spatial.mixer_of(self.controller)
        if mixer is None:
            raise VibsynthError(NO_LAYOUT)
        return mixer

    @staticmethod
    def _each(sources: tuple[int, ...] | None, change: Callable[[SourceTable, int, float], None]) -> Update:
        indices = tuple(sources or ())

        def update(table: SourceTable, t: float) -> None:
            for index in indices:
                change(table, index, t)

        return update

    # ------------------------------------------------------------------ setters
    def _on_pos(self, msg: Message, sources, peer: PeerLike, at_frame: int | None) -> None:
        arg_count(msg, (2, 3), "x, y[, z] in metres")
        mixer = self._mixer()
        position = mixer.table.check_position(tuple(number(msg, i, "xyz"[i]) for i in range(len(msg.args))))
        mixer.apply(self._each(sources, lambda table, i, t: table.set_position(i, position, t)), at_frame=at_frame)

    def _on_texture(self, msg: Message, sources, peer: PeerLike, at_frame: int | None) -> None:
        arg_count(msg, (2,), "intensity, balance")
        mixer = self._mixer()
        intensity = mixer.table.check_intensity(number(msg, 0, "intensity"))
        balance = mixer.table.check_balance(number(msg, 1, "balance"))
        mixer.apply(
            self._each(sources, lambda table, i, t: table.set_texture(i, intensity, balance)), at_frame=at_frame
        )

    def _on_intensity(self, msg: Message, sources, peer: PeerLike, at_frame: int | None) -> None:
        arg_count(msg, (1,), "intensity 0..1")
        mixer = self._mixer()
        intensity = mixer.table.check_intensity(number(msg, 0, "intensity"))
        mixer.apply(
            self._each(sources, lambda table, i, t: table.set_texture(i, intensity=intensity)), at_frame=at_frame
        )

    def _on_balance(self, msg: Message, sources, peer: PeerLike, at_frame: int | None) -> None:
        arg_count(msg, (1,), "balance")
        mixer = self._mixer()
        balance = mixer.table.check_balance(number(msg, 0, "balance"))
        mixer.apply(self._each(sources, lambda table, i, t: table.set_texture(i, balance=balance)), at_frame=at_frame)

    def _on_preset(self, msg: Message, sources, peer: PeerLike, at_frame: int | None) -> None:
        arg_count(msg, (1,), "preset name")
        mixer = self._mixer()
        preset = mixer.table.resolve_preset(string(msg, 0, "preset"))
        mixer.apply(self._each(sources, lambda table, i, t: table.set_preset(i, preset)), at_frame=at_frame)

    def _on_radius(self, msg: Message, sources, peer: PeerLike, at_frame: int | None) -> None:
        arg_count(msg, (1,), "radius in metres")
        mixer = self._mixer()
        radius = mixer.table.check_radius(number(msg, 0, "radius (m)"))
        mixer.apply(self._each(sources, lambda table, i, t: table.set_radius(i, radius)), at_frame=at_frame)

    def _on_rolloff(self, msg: Message, sources, peer: PeerLike, at_frame: int | None) -> None:
        arg_count(msg, (1,), "linear, smooth, inverse-square or phantom")
        mixer = self._mixer()
        law = check_rolloff(string(msg, 0, "roll-off"))
        mixer.apply(self._each(sources, lambda table, i, t: table.set_rolloff(i, law)), at_frame=at_frame)

    def _on_on(self, msg: Message, sources, peer: PeerLike, at_frame: int | None) -> None:
        arg_count(msg, (1,), "1 = on, 0 = off")
        on = flag(msg, 0, "on")
        self._mixer().apply(self._each(sources, lambda table, i, t: table.set_on(i, on, t)), at_frame=at_frame)

    def _on_speed(self, msg: Message, sources, peer: PeerLike, at_frame: int | None) -> None:
        arg_count(msg, (1,), "1 = intensity from the source's speed, 0 = its own")
        speed = flag(msg, 0, "speed")
        self._mixer().apply(self._each(sources, lambda table, i, t: table.set_speed(i, speed)), at_frame=at_frame)

    # ------------------------------------------------------------------ queries
    def _on_get(self, msg: Message, sources, peer: PeerLike, at_frame: int | None) -> None:
        arg_count(msg, (1,), "setting name")
        name = string(msg, 0, "setting")
        if name not in SETTING_NAMES:
            raise ParameterError(f"unknown source setting {name!r}; known: {', '.join(SETTING_NAMES)}")
        indices = tuple(sources or ())
        views: list[SourceView] = self._mixer().read(lambda table, now: [table.view(i, now) for i in indices])
        for view in views:
            peer.send(self.reply(view, name))

    def reply(self, view: SourceView, name: str) -> bytes:
        """A source's setting in setter form, e.g. ``/vibsynth/source/2/pos fff``."""
        base = f"{self.prefix}/source/{view.index + 1}/{name}"
        values: dict[str, tuple[Sequence[object], str]] = {
            "pos": (view.target, "fff"),
            "texture": ((view.intensity, view.balance), "ff"),
            "intensity": ((view.intensity,), "f"),
            "balance": ((view.balance,), "f"),
            "preset": ((view.preset or "",), "s"),
            "radius": ((view.radius,), "f"),
            "rolloff": ((view.rolloff,), "s"),
            "on": ((int(view.on),), "i"),
            "speed": ((int(view.speed),), "i"),
        }
        args, types = values[name]
        return encode_message(base, args, types)
