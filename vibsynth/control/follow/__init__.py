"""Follow, live: an input (a sound card, JACK ports, a WAV file) tracked and played as a texture (docs/follow.md).

* :mod:`~vibsynth.control.follow.routes` - which inputs drive which channel or source, with which
  tracker parameters;
* :mod:`~vibsynth.control.follow.transients` - onsets as clip-like transients;
* :mod:`~vibsynth.control.follow.follower` - the worker: input ring -> trackers -> the
  controller's ``follow`` layer; loss, recovery, live gain/gate/focus, per-channel on/off, the
  snapshot and trace a panel polls;
* :mod:`~vibsynth.control.follow.service` - ``vibsynth serve``'s wiring (the input source from
  ``follow.device`` and the follower, started and stopped with the service).

The OSC methods (``/vibsynth/follow/...``, ``/vibsynth/ch/{n}/follow``) are in
:mod:`vibsynth.control.osc.follow`; they find the running follower with :func:`follower_of`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from vibsynth.control.registry import Registry

if TYPE_CHECKING:
    from vibsynth.control.follow.follower import Follower

__all__ = ["attach", "detach", "follower_of"]

_followers: Registry[Follower] = Registry()


def attach(controller: Any, follower: Follower) -> None:
    """Make ``follower`` the running follower of ``controller`` (what :func:`follower_of` returns)."""
    _followers.attach(controller, follower)


def detach(controller: Any, follower: Follower) -> None:
    """Forget ``follower`` (if it is still the controller's)."""
    _followers.detach(controller, follower)


def follower_of(controller: Any) -> Follower | None:
    """The running follower of ``controller``, or None (follow is off)."""
    return _followers.of(controller)
