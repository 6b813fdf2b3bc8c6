"""control/midi: MIDI input -> knob moves (bindings, mapper, server, learn store, adapter)."""

from __future__ import annotations

from collections.abc import Callable

__all__ = ["learn_hook"]


def learn_hook() -> Callable[[str], bool] | None:
    """``vibsynth.control.midi.adapter.learn`` (arms MIDI learn on the running inputs), or None without MIDI.

    For the other control surfaces (OSC ``/learn``, the studio's learn buttons); MIDI is
    optional (python-rtmidi may be missing), so importing it may fail.
    """
    try:
        from vibsynth.control.midi import adapter
    except Exception:  # noqa: BLE001 - MIDI is optional
        return None
    hook = getattr(adapter, "learn", None)
    return hook if callable(hook) else None
