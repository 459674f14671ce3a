"""The physics mismatch finder (``trainer diagnose``): what a user's simulation leaves out of a recording.

Pipeline (docs/diagnose.md): block means of the recording (:mod:`.blocks`); what the temperature
profile can identify (:mod:`.profile`); the user's simulation calibrated as the baseline
(:mod:`.baseline`, :mod:`.model`, GLS under the IEEE 952 noise model in :mod:`.gls`); a search
per catalogue effect (:mod:`.candidates`); selection by BIC and confounder checks
(:mod:`.select`); where the residual is structured (:mod:`.locate`); the report (:mod:`.report`).
"""

from __future__ import annotations

from trainer.diagnose.run import Diagnosis, diagnose

__all__ = ["Diagnosis", "diagnose"]
