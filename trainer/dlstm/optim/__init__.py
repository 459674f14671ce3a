"""Population optimisers of the DLSTM + ISSA fusion: SSA / ISSA and Mantegna Lévy steps."""

from trainer.dlstm.optim.levy import levy_step, mantegna_sigma
from trainer.dlstm.optim.ssa import OptimizeResult, SsaSettings, minimize

__all__ = ["OptimizeResult", "SsaSettings", "levy_step", "mantegna_sigma", "minimize"]
