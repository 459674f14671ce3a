"""``hysteresis_offset`` streamed: the play operator and branch offset of ``hysteresis`` (the same C),
the polynomial keeps reading ``T_pm``."""

from __future__ import annotations

from trainer.physics.catalogue.hysteresis_offset import DEFINITION
from trainer.physics.catalogue.hysteresis_stream import branch

STREAMED = branch(DEFINITION.identifier, reads_play=False)
