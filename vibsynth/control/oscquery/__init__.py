"""OSCQuery and mDNS discovery: the OSC address space as a JSON tree, found by tools on the network.

* :mod:`~vibsynth.control.oscquery.tree` - nodes and the proposal's attribute rules;
* :mod:`~vibsynth.control.oscquery.methods` - the OSC methods as nodes (ranges from the settings);
* :mod:`~vibsynth.control.oscquery.server` - HTTP + WebSocket (LISTEN, value pushes, structure changes);
* :mod:`~vibsynth.control.oscquery.discovery` - zeroconf advertising and browsing;
* :mod:`~vibsynth.control.oscquery.adapter` - ``serve`` flags and construction from ``discovery:``.
"""
