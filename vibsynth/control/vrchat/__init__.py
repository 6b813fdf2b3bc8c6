"""The VRChat bridge: avatar parameters (Contact Receivers) drive touch sources, channels, presets and clips.

* :mod:`~vibsynth.control.vrchat.drives` - the ``level`` and ``velocity`` drives (pure state);
* :mod:`~vibsynth.control.vrchat.bridge` - the ``/avatar/`` namespace of the OSC handler;
* :mod:`~vibsynth.control.vrchat.finder` - VRChat found over mDNS (its OSCQuery HOST_INFO);
* :mod:`~vibsynth.control.vrchat.adapter` - ``vibsynth serve``'s wiring (``vrchat:``; docs/vr.md).
"""
