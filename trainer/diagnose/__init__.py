"""The physics mismatch finder (``trainer diagnose``): what a user's simulation leaves out of a recording.

Pipeline (docs/diagnose.md): block means of the recording (:mod:`.blocks`); what the temperature
profile can identify (:mod:`.profile`); the user's simulation calibrated as the baseline
(:mod:`.baseline`, :mod:`.model`, GLS under the IEEE 952 noise model in :mod:`.gls`); a search
per catalogue effect (:mod:`.candidates`); selection by BIC and confounder checks
(:mod:`.select`); where the residual is structured (:mod:`.where` on the scans of :mod:`.locate`);
fit summaries (:mod:`.fit_summary`), the held-out check (:mod:`.holdout`), the augmented simulation
(:mod:`.augmented`); typed results (:mod:`.result`), the JSON document (:mod:`.document`) and the
report (:mod:`.report`).
"""

from __future__ import annotations

from trainer.diagnose.result import Diagnosis
from trainer.diagnose.run import diagnose

__all__ = ["Diagnosis", "diagnose"]
