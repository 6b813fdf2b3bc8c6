"""The perception lab: the paper's three experiments on one's own actuator, stimuli and participants.

Pure research code (no engine, no server): stimulus sets (:mod:`.stimuli`), seeded trial
orders (:mod:`.orders`), session folders and their CSV (:mod:`.session`, :mod:`.records`),
making a session (:mod:`.build`) and the analysis (:mod:`.analysis`). Playing the stimuli on
the actuator and the studio's Lab page are in :mod:`vibsynth.app.lab`; docs/lab.md explains
the protocols.
"""

from vibsynth.research.lab.protocol import PROTOCOLS, VERSIONS, LabParameters

__all__ = ["PROTOCOLS", "VERSIONS", "LabParameters"]
