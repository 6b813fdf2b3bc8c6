"""The studio: a browser workspace served by ``vibsynth serve`` over HTTP + WebSocket (docs/studio.md).

* :mod:`~vibsynth.control.studio.server` - the aiohttp application on its own loop thread;
* :mod:`~vibsynth.control.studio.security` - token, Origin, Host and size checks;
* :mod:`~vibsynth.control.studio.hub` - coalesced pushes to the open pages;
* :mod:`~vibsynth.control.studio.commands` - what a page may ask (through the Controller);
* the panels: :mod:`~vibsynth.control.studio.status` (and presets, recording, spectrum);
* :mod:`~vibsynth.control.studio.extension` - the hook other parts add tabs with;
* :mod:`~vibsynth.control.studio.adapter` - flags, construction, opening a browser.
"""
