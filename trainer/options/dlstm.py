"""Command-line options shared by ``trainer fit`` and ``trainer compare`` for the DLSTM methods."""

from __future__ import annotations

import argparse
from typing import Any

from trainer.budget import FLOAT_BYTES, check_memory, check_time
from trainer.dlstm.realtime import (
    DEFAULT_STEP_S,
    DEFAULT_TEMP_SMOOTHING_S,
    PAPER_RUN_SMOOTHING_S,
    PAPER_TRAIN_SMOOTHING_S,
)
from trainer.errors import UserError
from trainer.options.numbers import MAX_SECONDS, check_finite, check_threads
from trainer.options.seed import seed

# Size estimates for the budget, at the size of the paper's run (2 h at the 1 s network step):
# a longer recording only costs more, so a refusal here is never wrong.
REFERENCE_STEPS = 7200
# One network, one iteration at hidden 10 and 2 layers: 55 s for 10 networks x 500 iterations.
SECONDS_PER_NETWORK_ITERATION = 0.011
VALUES_PER_UNIT_STEP = 10  # kept for back-propagation per LSTM unit and step (gates, states)
VALUES_PER_WEIGHT = 4  # the weight, its gradient and Adam's two moments
_SMALLER = "use a smaller --population, --hidden, --layers, --iterations or --cycles"


def add_dlstm_options(parser: argparse.ArgumentParser) -> None:
    group = parser.add_argument_group("DLSTM and fusion (defaults: the paper's section 4 settings)")
    group.add_argument("--population", type=int, default=10, help="DLSTMs in the population (10)")
    group.add_argument("--hidden", type=int, default=10, help="units per LSTM layer (10)")
    group.add_argument("--layers", type=int, default=2, help="stacked LSTM layers (2)")
    group.add_argument("--lr", type=float, default=0.02, help="Adam learning rate (0.02)")
    group.add_argument(
        "--iterations", type=int, default=500, help="gradient iterations, ending condition one (500)"
    )
    group.add_argument("--cycles", type=int, default=200, help="SSA/ISSA cycles, ending condition two (200)")
    group.add_argument("--target-loss", type=float, default=None, help="stop early at this training MSE")
    group.add_argument("--seed", type=seed, default=0, help="seed of every random step (0)")
    group.add_argument(
        "--train-smoothing",
        type=float,
        default=PAPER_TRAIN_SMOOTHING_S,
        help="training smoothing in s (paper: 5)",
    )
    group.add_argument(
        "--run-smoothing",
        type=float,
        default=PAPER_RUN_SMOOTHING_S,
        help="run-time smoothing in s (paper: 0.5)",
    )
    group.add_argument(
        "--temp-smoothing",
        type=float,
        default=DEFAULT_TEMP_SMOOTHING_S,
        help="temperature smoothing in s (5)",
    )
    group.add_argument(
        "--step", type=float, default=DEFAULT_STEP_S, help="network step (decimation) in s (1)"
    )
    group.add_argument("--threads", type=int, default=1, help="torch threads (1 is fastest for these sizes)")
    group.add_argument("--quiet", action="store_true", help="no progress bars")


MAX_LR = (
    10.0  # Adam's step on standardised data: above this every network diverges (1e300 overflowed float32)
)


def settings_from_args(args: argparse.Namespace) -> tuple[Any, dict[str, float]]:
    """(FusionSettings, front-end seconds) from parsed options, each checked with a clear message."""
    from trainer.dlstm.fusion import FusionSettings

    positive_ints = ("population", "hidden", "layers")
    for name in positive_ints:
        if getattr(args, name) < 1:
            raise UserError(f"--{name} must be >= 1, got {getattr(args, name)}")
    check_threads(args.threads)
    if args.iterations < 1:  # 0 trained nothing: the networks' initial weights were written as a model
        raise UserError(f"--iterations must be >= 1 (the networks train by it), got {args.iterations}")
    if args.cycles < 0:
        raise UserError(f"--cycles must be >= 0, got {args.cycles}")
    check_finite("--lr", args.lr, inclusive=False, maximum=MAX_LR)
    for name in ("train_smoothing", "run_smoothing", "temp_smoothing", "step"):
        check_finite(f"--{name.replace('_', '-')}", getattr(args, name), inclusive=False, maximum=MAX_SECONDS)
    if args.target_loss is not None:
        check_finite("--target-loss", args.target_loss)
    check_dlstm_size(args.population, args.hidden, args.layers, args.iterations, args.cycles)
    import torch

    torch.set_num_threads(args.threads)
    settings = FusionSettings(
        population=args.population,
        hidden_size=args.hidden,
        num_layers=args.layers,
        lr=args.lr,
        iterations=args.iterations,
        cycles=args.cycles,
        target_loss=args.target_loss,
        seed=args.seed,
    )
    frontend = {
        "run_smoothing_s": args.run_smoothing,
        "temp_smoothing_s": args.temp_smoothing,
        "step_s": args.step,
        "train_smoothing_s": args.train_smoothing,
    }
    return settings, frontend


def check_dlstm_size(population: int, hidden: int, layers: int, iterations: int, cycles: int) -> None:
    """Refuse a population whose memory or run time (at the paper's run size) is above the budget."""
    what = f"DLSTM --population {population} --hidden {hidden} --layers {layers}"
    networks = float(population) * layers
    weights = networks * 8.0 * hidden * (hidden + 1)  # four gates, input and recurrent weights
    activations = networks * hidden * REFERENCE_STEPS * VALUES_PER_UNIT_STEP
    check_memory((weights * VALUES_PER_WEIGHT + activations) * FLOAT_BYTES, what, _SMALLER)
    scale = max(hidden / 10.0, 1.0) ** 2 * layers / 2.0
    seconds = float(population) * (iterations + cycles) * scale * SECONDS_PER_NETWORK_ITERATION
    check_time(seconds, f"{what} --iterations {iterations} --cycles {cycles}", _SMALLER)
