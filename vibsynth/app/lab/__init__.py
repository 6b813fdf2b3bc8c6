"""The perception lab on the engine and in the studio: the runner that plays sessions on the
actuator (:mod:`.runner`) and the studio's Lab tab (:mod:`.studio`, ``static/``).

The protocols, sessions and analysis are pure research code in :mod:`vibsynth.research.lab`.
"""
