"""A population of P independent stacked-LSTM networks (the paper's DLSTM) held as one module.

Why a population: the fusion algorithm (Guo et al. 2023, section 3.1.4) trains N = 10 networks
and then hands them to the sparrow search as an (N, d) matrix whose fitness is evaluated for the
whole population at once. Every weight therefore has a leading population dimension P.

Equations (paper eq. (2)-(7)), per layer, per individual, with one bias per gate::

    i_t = sigma(W_ix x_t + W_ih h_{t-1} + b_i)        f_t = sigma(W_fx x_t + W_fh h_{t-1} + b_f)
    g_t = tanh (W_gx x_t + W_gh h_{t-1} + b_g)        o_t = sigma(W_ox x_t + W_oh h_{t-1} + b_o)
    C_t = C_{t-1} * f_t + i_t * g_t                   h_t = tanh(C_t) * o_t

with h_0 = C_0 = 0. Layer l+1 reads layer l's h_t; a linear head maps the last layer's h_t to y_t.

Gate order: the 4H rows of every ``w_x``/``w_h``/``b`` are the blocks **i, f, g, o** (input,
forget, cell candidate, output), the same order as ``torch.nn.LSTM``, so an individual copies
into ``nn.LSTM`` unchanged (its single bias goes to ``bias_ih``, ``bias_hh`` = 0).

Parameters, for layer l (``in_0 = input_size``, ``in_l = hidden_size`` for l >= 1)::

    w_x{l}: (P, 4H, in_l)   w_h{l}: (P, 4H, H)   b{l}: (P, 4H)   w_out: (P, out, H)   b_out: (P, out)

Flat layout (``flatten``/``load_flat``/``forward_flat``; stable, the sparrow search's rows):
row k of the (P, d) matrix is the concatenation, in this order, of
``w_x0[k], w_h0[k], b0[k], w_x1[k], w_h1[k], b1[k], ..., w_out[k], b_out[k]``, each flattened
row-major (matrices: gate block, then unit, then input column). d = sum_l 4H (in_l + H + 1) +
out (H + 1); 1331 for the paper's 2 layers x 10 units, input 1, output 1.

Two implementations of the same recurrence:

* ``backend="packed"`` (default, fast): the P networks are packed block-diagonally into one
  ``torch.lstm`` call of hidden size g*H per group of at most ``group_size`` individuals, so the
  time loop runs in ATen/oneDNN instead of Python. Off-diagonal blocks are exact zeros, so each
  individual only sees its own weights. Because 0 * NaN = NaN would leak through the packed
  matmul, individuals with non-finite parameters are evaluated as zeros and reported as NaN, and
  a NaN arising inside a finite individual triggers a re-run with one individual per call.
  float32 uses oneDNN; its training and no-grad primitives agree to rounding, not bit for bit.
* ``backend="loop"`` (reference): a Python loop over :func:`dlstm_step`, literal eq. (2)-(7)
  with batched matmuls over the population. It is what the C code reproduces step by step.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
import torch
from torch import Tensor, nn

GATE_ORDER: tuple[str, ...] = ("i", "f", "g", "o")
# Individuals per packed torch.lstm call. The packed matmul is dense, so its cost grows as g^2 while
# the per-step overhead is shared: measured optimum g = 4 for H = 10 (2 cores, float32, T = 1440 and
# 14400: about 2x faster per individual than g = 1 or g = 10).
DEFAULT_GROUP_SIZE = 4

Backend = Literal["packed", "loop"]
Init = Literal["matlab", "pytorch"]
LayerState = tuple[Tensor, Tensor]  # (h, c), each (P, B, H)
State = tuple[LayerState, ...]  # one (h, c) per layer


@dataclass(frozen=True)
class LstmShape:
    """Architecture of one individual; everything the flat layout depends on."""

    input_size: int
    hidden_size: int = 10
    num_layers: int = 2
    output_size: int = 1

    def __post_init__(self) -> None:
        for name in ("input_size", "hidden_size", "num_layers", "output_size"):
            if int(getattr(self, name)) < 1:
                raise ValueError(f"LstmShape.{name} must be >= 1, got {getattr(self, name)}")

    def layer_input_size(self, layer: int) -> int:
        return self.input_size if layer == 0 else self.hidden_size

    def param_shapes(self) -> tuple[tuple[str, tuple[int, ...]], ...]:
        """(name, per-individual shape) in flat-layout order."""
        G = 4 * self.hidden_size
        shapes: list[tuple[str, tuple[int, ...]]] = []
        for layer in range(self.num_layers):
            shapes += [
                (f"w_x{layer}", (G, self.layer_input_size(layer))),
                (f"w_h{layer}", (G, self.hidden_size)),
                (f"b{layer}", (G,)),
            ]
        shapes += [("w_out", (self.output_size, self.hidden_size)), ("b_out", (self.output_size,))]
        return tuple(shapes)

    @property
    def num_params(self) -> int:
        """d, the length of one individual's parameter vector."""
        return sum(math.prod(shape) for _, shape in self.param_shapes())


# --------------------------------------------------------------------------------------------
# Functional core: ``params`` is a list of (P, *shape) tensors in flat-layout order.
# --------------------------------------------------------------------------------------------


def split_flat(theta: Tensor, spec: LstmShape) -> list[Tensor]:
    """Views of a (P, d) parameter matrix as the (P, *shape) tensors of the flat layout."""
    if theta.dim() != 2 or theta.shape[1] != spec.num_params:
        raise ValueError(f"theta must be (P, {spec.num_params}), got {tuple(theta.shape)}")
    params, offset = [], 0
    for _, shape in spec.param_shapes():
        n = math.prod(shape)
        params.append(theta[:, offset : offset + n].reshape(theta.shape[0], *shape))
        offset += n
    return params


def zero_state(population: int, batch: int, spec: LstmShape, *, dtype: torch.dtype) -> State:
    """h_0 = C_0 = 0 for every layer (the paper initialises C to 0)."""
    shape = (population, batch, spec.hidden_size)
    return tuple(
        (torch.zeros(shape, dtype=dtype), torch.zeros(shape, dtype=dtype)) for _ in range(spec.num_layers)
    )


def dlstm_step(
    params: Sequence[Tensor], x_t: Tensor, spec: LstmShape, state: State | None = None
) -> tuple[Tensor, State]:
    """One time step of eq. (2)-(7) for every individual: x_t (P, B, in) or shared (B, in).

    Returns y_t (P, B, out) and the new state. Differentiable; the reference for the C code.
    """
    P = params[0].shape[0]
    inp = _check_input(x_t, spec, P, params[0].dtype, time_axis=False)
    B = inp.shape[-2]
    if inp.dim() == 2:
        inp = inp.expand(P, *inp.shape)
    state = _check_state(state, P, B, spec, params[0].dtype)
    H = spec.hidden_size
    new_state = []
    for layer, (h, c) in enumerate(state):
        w_x, w_h, b = params[3 * layer : 3 * layer + 3]
        gates = torch.baddbmm(b.unsqueeze(1), inp, w_x.transpose(1, 2))
        gates = torch.baddbmm(gates, h, w_h.transpose(1, 2))
        i = torch.sigmoid(gates[..., 0:H])  # eq. (3)
        f = torch.sigmoid(gates[..., H : 2 * H])  # eq. (2)
        g = torch.tanh(gates[..., 2 * H : 3 * H])  # eq. (4)
        o = torch.sigmoid(gates[..., 3 * H : 4 * H])  # eq. (5)
        c = c * f + i * g  # eq. (6)
        h = torch.tanh(c) * o  # eq. (7)
        new_state.append((h, c))
        inp = h
    w_out, b_out = params[-2], params[-1]
    y = torch.baddbmm(b_out.unsqueeze(1), inp, w_out.transpose(1, 2))
    return y, tuple(new_state)


def dlstm_forward(
    params: Sequence[Tensor],
    x: Tensor,
    spec: LstmShape,
    state: State | None = None,
    *,
    backend: Backend = "packed",
    group_size: int = DEFAULT_GROUP_SIZE,
) -> tuple[Tensor, State]:
    """Run every individual over a sequence: x (P, B, T, in) or shared (B, T, in) -> y (P, B, T, out)."""
    P = params[0].shape[0]
    x = _check_input(x, spec, P, params[0].dtype, time_axis=True)
    B = x.shape[-3]
    state = _check_state(state, P, B, spec, params[0].dtype)
    if backend == "loop":
        ys = []
        for t in range(x.shape[-2]):
            y_t, state = dlstm_step(params, x[..., t, :], spec, state)
            ys.append(y_t)
        return torch.stack(ys, dim=2), state
    if backend != "packed":
        raise ValueError(f"backend must be 'packed' or 'loop', got {backend!r}")
    if group_size < 1:
        raise ValueError(f"group_size must be >= 1, got {group_size}")
    return _forward_packed(list(params), x, spec, state, group_size)


def forward_flat(
    theta: Tensor,
    x: Tensor,
    spec: LstmShape,
    state: State | None = None,
    *,
    backend: Backend = "packed",
    group_size: int = DEFAULT_GROUP_SIZE,
) -> tuple[Tensor, State]:
    """:func:`dlstm_forward` for a (P', d) parameter matrix; never touches a module."""
    return dlstm_forward(split_flat(theta, spec), x, spec, state, backend=backend, group_size=group_size)


# --------------------------------------------------------------------------------------------
# The module
# --------------------------------------------------------------------------------------------


class PopulationDLSTM(nn.Module):
    """P independent DLSTM networks trained and evaluated as one batch (see module docstring)."""

    def __init__(
        self,
        population: int,
        input_size: int,
        hidden_size: int = 10,
        num_layers: int = 2,
        output_size: int = 1,
        *,
        seed: int,
        init: Init = "matlab",
        dtype: torch.dtype = torch.float32,
        backend: Backend = "packed",
        group_size: int = DEFAULT_GROUP_SIZE,
    ) -> None:
        super().__init__()
        if population < 1:
            raise ValueError(f"population must be >= 1, got {population}")
        self.spec = LstmShape(input_size, hidden_size, num_layers, output_size)
        self.backend: Backend = backend
        self.group_size = group_size
        for name, shape in self.spec.param_shapes():
            self.register_parameter(name, nn.Parameter(torch.empty(population, *shape, dtype=dtype)))
        with torch.no_grad():
            for k in range(population):
                for p, value in zip(
                    self.param_list(), init_individual(self.spec, seed, k, init), strict=True
                ):
                    p[k].copy_(value)

    @property
    def population(self) -> int:
        return int(self.get_parameter("w_out").shape[0])

    @property
    def num_params(self) -> int:
        """d, parameters per individual."""
        return self.spec.num_params

    def param_list(self) -> list[nn.Parameter]:
        """The parameters in flat-layout order."""
        return [getattr(self, name) for name, _ in self.spec.param_shapes()]

    def forward(self, x: Tensor, state: State | None = None) -> tuple[Tensor, State]:
        """x (P, B, T, in) or shared (B, T, in) -> (y (P, B, T, out), final per-layer (h, c))."""
        return dlstm_forward(
            self.param_list(), x, self.spec, state, backend=self.backend, group_size=self.group_size
        )

    def step(self, x_t: Tensor, state: State | None = None) -> tuple[Tensor, State]:
        """One time step, x_t (P, B, in) or (B, in) -> y_t (P, B, out); for streaming use."""
        return dlstm_step(self.param_list(), x_t, self.spec, state)

    def flatten(self) -> Tensor:
        """The (P, d) parameter matrix (a detached copy) in the documented flat layout."""
        P = self.population
        return torch.cat([p.detach().reshape(P, -1) for p in self.param_list()], dim=1)

    @torch.no_grad()
    def load_flat(self, theta: Tensor) -> None:
        """Overwrite all parameters from a (P, d) matrix (same P as the module)."""
        if theta.shape[0] != self.population:
            raise ValueError(f"theta has {theta.shape[0]} rows, the population has {self.population}")
        for p, value in zip(self.param_list(), split_flat(theta, self.spec), strict=True):
            p.copy_(value)

    def forward_flat(self, theta: Tensor, x: Tensor, state: State | None = None) -> tuple[Tensor, State]:
        """Forward with candidate parameters ``theta`` (P', d), any P'; the module is not modified."""
        return forward_flat(theta, x, self.spec, state, backend=self.backend, group_size=self.group_size)

    def individual(self, k: int) -> dict[str, Tensor]:
        """Network ``k`` as plain tensors (no population dim), keys in flat-layout order."""
        if not -self.population <= k < self.population:
            raise IndexError(f"individual {k} out of range for population {self.population}")
        return {name: getattr(self, name)[k].detach().clone() for name, _ in self.spec.param_shapes()}

    @classmethod
    def from_individuals(
        cls,
        individuals: Sequence[Mapping[str, Tensor]],
        *,
        dtype: torch.dtype | None = None,
        backend: Backend = "packed",
        group_size: int = DEFAULT_GROUP_SIZE,
    ) -> PopulationDLSTM:
        """Rebuild a population from :meth:`individual` dicts (e.g. a loaded model.pt).

        The architecture is read from the shapes; ``dtype`` defaults to the tensors' dtype.
        """
        if not individuals:
            raise ValueError("from_individuals needs at least one individual")
        first = individuals[0]
        num_layers = sum(1 for name in first if name.startswith("w_h"))
        G, input_size = first["w_x0"].shape
        spec = LstmShape(input_size, G // 4, num_layers, first["w_out"].shape[0])
        model = cls(
            len(individuals),
            spec.input_size,
            spec.hidden_size,
            spec.num_layers,
            spec.output_size,
            seed=0,  # every weight is overwritten below
            dtype=dtype or first["w_x0"].dtype,
            backend=backend,
            group_size=group_size,
        )
        with torch.no_grad():
            for k, ind in enumerate(individuals):
                for name, shape in spec.param_shapes():
                    if name not in ind or tuple(ind[name].shape) != shape:
                        got = tuple(ind[name].shape) if name in ind else "missing"
                        raise ValueError(f"individual {k}: '{name}' must have shape {shape}, got {got}")
                    getattr(model, name)[k].copy_(ind[name])
        return model

    def to_torch_lstm(self, k: int) -> tuple[nn.LSTM, nn.Linear]:
        """Network ``k`` as ``nn.LSTM(batch_first=True)`` + ``nn.Linear`` with identical weights."""
        ind, s = self.individual(k), self.spec
        dtype = ind["w_x0"].dtype
        lstm = nn.LSTM(s.input_size, s.hidden_size, s.num_layers, batch_first=True, dtype=dtype)
        head = nn.Linear(s.hidden_size, s.output_size, dtype=dtype)
        with torch.no_grad():
            for layer in range(s.num_layers):
                getattr(lstm, f"weight_ih_l{layer}").copy_(ind[f"w_x{layer}"])
                getattr(lstm, f"weight_hh_l{layer}").copy_(ind[f"w_h{layer}"])
                getattr(lstm, f"bias_ih_l{layer}").copy_(ind[f"b{layer}"])
                getattr(lstm, f"bias_hh_l{layer}").zero_()
            head.weight.copy_(ind["w_out"])
            head.bias.copy_(ind["b_out"])
        return lstm, head

    def extra_repr(self) -> str:
        s = self.spec
        return (
            f"population={self.population}, input_size={s.input_size}, hidden_size={s.hidden_size}, "
            f"num_layers={s.num_layers}, output_size={s.output_size}, d={s.num_params}, "
            f"backend={self.backend!r}"
        )


# --------------------------------------------------------------------------------------------
# Initialisation
# --------------------------------------------------------------------------------------------


def individual_generator(seed: int, k: int) -> torch.Generator:
    """A generator for individual ``k`` that depends only on (seed, k), not on the population size."""
    if seed < 0:
        raise ValueError(f"seed must be >= 0, got {seed}")
    words = np.random.SeedSequence(seed, spawn_key=(k,)).generate_state(2, dtype=np.uint32)
    return torch.Generator().manual_seed((int(words[0]) << 32 | int(words[1])) & ((1 << 63) - 1))


def init_individual(spec: LstmShape, seed: int, k: int, init: Init = "matlab") -> list[Tensor]:
    """Initial float64 weights of individual ``k`` in flat-layout order.

    ``"matlab"`` mirrors MATLAB's lstmLayer/fullyConnectedLayer defaults (the paper used MATLAB):
    Glorot-uniform input and head weights, orthogonal recurrent weights, unit forget-gate bias,
    zero head bias. ``"pytorch"`` is U(-1/sqrt(H), 1/sqrt(H)) everywhere (single bias).
    """
    gen = individual_generator(seed, k)
    H, G = spec.hidden_size, 4 * spec.hidden_size

    def uniform(shape: tuple[int, ...], bound: float) -> Tensor:
        return (torch.rand(shape, generator=gen, dtype=torch.float64) * 2.0 - 1.0) * bound

    out: list[Tensor] = []
    for layer in range(spec.num_layers):
        n_in = spec.layer_input_size(layer)
        if init == "matlab":
            w_x = uniform((G, n_in), math.sqrt(6.0 / (n_in + G)))
            q, r = torch.linalg.qr(torch.randn((G, H), generator=gen, dtype=torch.float64))
            w_h = q * torch.where(torch.diagonal(r) < 0, -1.0, 1.0)
            b = torch.zeros(G, dtype=torch.float64)
            b[H : 2 * H] = 1.0
        elif init == "pytorch":
            bound = 1.0 / math.sqrt(H)
            w_x, w_h, b = uniform((G, n_in), bound), uniform((G, H), bound), uniform((G,), bound)
        else:
            raise ValueError(f"init must be 'matlab' or 'pytorch', got {init!r}")
        out += [w_x, w_h, b]
    if init == "matlab":
        out += [
            uniform((spec.output_size, H), math.sqrt(6.0 / (H + spec.output_size))),
            torch.zeros(spec.output_size, dtype=torch.float64),
        ]
    else:
        out += [
            uniform((spec.output_size, H), 1.0 / math.sqrt(H)),
            uniform((spec.output_size,), 1.0 / math.sqrt(H)),
        ]
    return out


# --------------------------------------------------------------------------------------------
# Internals
# --------------------------------------------------------------------------------------------


def _check_input(x: Tensor, spec: LstmShape, P: int, dtype: torch.dtype, *, time_axis: bool) -> Tensor:
    shared_dims = 3 if time_axis else 2
    what = "(B, T, in) or (P, B, T, in)" if time_axis else "(B, in) or (P, B, in)"
    if x.dim() not in (shared_dims, shared_dims + 1) or x.shape[-1] != spec.input_size:
        raise ValueError(f"input must be {what} with in={spec.input_size}, got {tuple(x.shape)}")
    if x.dim() == shared_dims + 1 and x.shape[0] != P:
        raise ValueError(f"input has population dim {x.shape[0]}, the parameters have {P}")
    if x.dtype != dtype:
        raise ValueError(f"input dtype {x.dtype} differs from parameter dtype {dtype}")
    return x


def _check_state(state: State | None, P: int, B: int, spec: LstmShape, dtype: torch.dtype) -> State:
    if state is None:
        return zero_state(P, B, spec, dtype=dtype)
    expected = (P, B, spec.hidden_size)
    if len(state) != spec.num_layers or any(
        tuple(t.shape) != expected for layer_state in state for t in layer_state
    ):
        raise ValueError(f"state must be {spec.num_layers} pairs (h, c) of shape {expected}")
    return tuple((h, c) for h, c in state)


def _gate_major(w: Tensor, H: int) -> Tensor:
    """(P, 4H, K) -> (4PH, K): rows ordered gate, individual, unit (torch.lstm's layout for hidden PH)."""
    P, _, K = w.shape
    return w.reshape(P, 4, H, K).transpose(0, 1).reshape(4 * P * H, K)


def _block_diag_gate_major(w: Tensor, H: int) -> Tensor:
    """(P, 4H, K) -> (4PH, PK) with individual p's weights only in its own (rows, columns) block.

    Built with index_put so that neither direction ever multiplies by the zero blocks.
    """
    P, _, K = w.shape
    dense = w.new_zeros(4, P, H, P, K)
    idx = torch.arange(P)
    dense[:, idx, :, idx, :] = w.reshape(P, 4, H, K)  # advanced dims first: (P, 4, H, K)
    return dense.reshape(4 * P * H, P * K)


def _pack_hidden(t: Tensor) -> Tensor:
    """(P, B, H) -> (B, P*H)."""
    P, B, H = t.shape
    return t.transpose(0, 1).reshape(B, P * H)


def _unpack_hidden(t: Tensor, P: int) -> Tensor:
    """(B, P*H) -> (P, B, H)."""
    B = t.shape[0]
    return t.reshape(B, P, -1).transpose(0, 1)


def _packed_group(
    params: list[Tensor], x: Tensor, spec: LstmShape, state: State
) -> tuple[Tensor, Tensor, State]:
    """One torch.lstm call for a group; returns (last-layer h sequence (P,B,T,H), y, state)."""
    P, H, L = params[0].shape[0], spec.hidden_size, spec.num_layers
    N = P * H
    flat: list[Tensor] = []
    for layer in range(L):
        w_x, w_h, b = params[3 * layer : 3 * layer + 3]
        shared_input = layer == 0 and x.dim() == 3
        flat += [
            _gate_major(w_x, H) if shared_input else _block_diag_gate_major(w_x, H),
            _block_diag_gate_major(w_h, H),
            _gate_major(b.unsqueeze(-1), H).squeeze(-1),
            b.new_zeros(4 * N),  # torch's second bias; the paper has one bias per gate
        ]
    if x.dim() == 4:  # per-individual inputs, packed along features: (B, T, P*in)
        B, T = x.shape[1], x.shape[2]
        x = x.permute(1, 2, 0, 3).reshape(B, T, P * spec.input_size)
    B, T = x.shape[0], x.shape[1]
    h0 = torch.stack([_pack_hidden(h) for h, _ in state])
    c0 = torch.stack([_pack_hidden(c) for _, c in state])
    out, h_n, c_n = torch.lstm(x, (h0, c0), flat, True, L, 0.0, torch.is_grad_enabled(), False, True)
    hs = out.reshape(B, T, P, H).permute(2, 0, 1, 3)
    w_out, b_out = params[-2], params[-1]
    y = torch.einsum("pbth,poh->pbto", hs, w_out) + b_out[:, None, None, :]
    new_state = tuple((_unpack_hidden(h_n[layer], P), _unpack_hidden(c_n[layer], P)) for layer in range(L))
    return hs, y, new_state


def packed_groups(population: int, group_size: int = DEFAULT_GROUP_SIZE) -> list[range]:
    """The individuals of each packed ``torch.lstm`` call: balanced groups of at most ``group_size``.

    An individual's arithmetic depends on its group only, so a group trains alone exactly as it
    does inside the whole population (``trainer compare --jobs`` trains the groups side by side).
    """
    size = max(1, min(group_size, population))
    n_groups = -(-population // size)
    bounds = [population * i // n_groups for i in range(n_groups + 1)]
    return [range(lo, hi) for lo, hi in itertools.pairwise(bounds)]


def _individual_mask(t: Tensor, mask: Tensor) -> Tensor:
    return mask.view(-1, *([1] * (t.dim() - 1)))


def _forward_packed(
    params: list[Tensor], x: Tensor, spec: LstmShape, state: State, group_size: int
) -> tuple[Tensor, State]:
    P = params[0].shape[0]
    per_individual_x = x.dim() == 4
    # Isolation: an individual with NaN/inf weights (or inputs/state) is evaluated with zeros and
    # reported as NaN, because inside the packed matmul 0 * NaN would contaminate the others.
    per_individual = [*params, *(s for pair in state for s in pair)] + ([x] if per_individual_x else [])
    bad = torch.zeros(P, dtype=torch.bool)
    for t in per_individual:
        bad |= ~torch.isfinite(t.detach()).reshape(P, -1).all(dim=1)
    if bad.any():

        def clean(t: Tensor) -> Tensor:
            return t.masked_fill(_individual_mask(t, bad), 0.0)

        params = [clean(p) for p in params]
        x = clean(x) if per_individual_x else x
        state = tuple((clean(h), clean(c)) for h, c in state)

    def run(size: int) -> tuple[bool, Tensor, State]:
        chunks = packed_groups(P, size)
        results = [
            _packed_group(
                [p[g.start : g.stop] for p in params],
                x[g.start : g.stop] if per_individual_x else x,
                spec,
                tuple((h[g.start : g.stop], c[g.start : g.stop]) for h, c in state),
            )
            for g in chunks
        ]
        # Whether every h is finite, per group: a NaN in h reaches y (NaN * w is NaN), so y, 1/H the
        # size, is checked first and h only when y is not finite (an overflow of the head).
        finite = all(
            bool(torch.isfinite(r[1].detach()).all()) or bool(torch.isfinite(r[0].detach()).all())
            for r in results
        )
        if len(results) == 1:
            return finite, results[0][1], results[0][2]
        y = torch.cat([r[1] for r in results])
        st = tuple(
            (torch.cat([r[2][layer][0] for r in results]), torch.cat([r[2][layer][1] for r in results]))
            for layer in range(spec.num_layers)
        )
        return finite, y, st

    size = max(1, min(group_size, P))
    finite, y, new_state = run(size)
    # With finite weights, inputs and state, h is bounded by tanh; a NaN here means some gate
    # overflowed (inf - inf) inside one individual and may have leaked through the packed matmul.
    # Re-run one individual per call so that no individual can affect another.
    if size > 1 and not finite and (per_individual_x or bool(torch.isfinite(x).all())):
        _, y, new_state = run(1)
    if bad.any():
        y = y.masked_fill(_individual_mask(y, bad), float("nan"))
        new_state = tuple(
            (
                h.masked_fill(_individual_mask(h, bad), float("nan")),
                c.masked_fill(_individual_mask(c, bad), float("nan")),
            )
            for h, c in new_state
        )
    return y, new_state
