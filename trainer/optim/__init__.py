"""Population optimisers of the DLSTM + ISSA fusion: SSA / ISSA and Mantegna Lévy steps."""

from trainer.optim.levy import levy_step, mantegna_sigma
from trainer.optim.ssa import OptimizeResult, minimize

__all__ = ["OptimizeResult", "levy_step", "mantegna_sigma", "minimize"]
