"""What other packages use of the mismatch finder: its one public interface.

``trainer/greybox`` fits the physics compensator with the finder's own machinery (block means,
the calibrated baseline, the GLS model and the candidate search) and names its structure with the
finder's verdict; it imports them from here only (tests/project/test_public_interfaces.py), so the
finder's modules can be split or renamed by changing this list.
"""

from __future__ import annotations

from trainer.diagnose.baseline import build_baseline
from trainer.diagnose.blocks import BlockData, build_blocks
from trainer.diagnose.candidates import propose, propose_freed_wide
from trainer.diagnose.model import Design, ModelFit, Term, build_design, evaluate, fit_model, search_bounds
from trainer.diagnose.profile import analyse_profile
from trainer.diagnose.result import Diagnosis
from trainer.diagnose.run import channel_scale, diagnose
from trainer.diagnose.threads import single_blas_thread
from trainer.diagnose.verdict import ambiguity_line, implausible_effects

__all__ = [
    "BlockData",
    "Design",
    "Diagnosis",
    "ModelFit",
    "Term",
    "ambiguity_line",
    "analyse_profile",
    "build_baseline",
    "build_blocks",
    "build_design",
    "channel_scale",
    "diagnose",
    "evaluate",
    "fit_model",
    "implausible_effects",
    "propose",
    "propose_freed_wide",
    "search_bounds",
    "single_blas_thread",
]
