"""PopulationDLSTM and its training, checked against torch.nn.LSTM and against training alone."""

from __future__ import annotations

import math

import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from trainer.dlstm.network import GATE_ORDER, LstmShape, PopulationDLSTM, forward_flat, split_flat
from trainer.dlstm.train import (
    clip_per_individual,
    one_step_ahead,
    per_individual_loss,
    population_loss,
    train_population,
)

F64 = torch.float64


def random_model(
    P: int = 3,
    input_size: int = 2,
    hidden: int = 5,
    layers: int = 2,
    out: int = 2,
    *,
    seed: int = 0,
    dtype: torch.dtype = F64,
    backend: str = "packed",
    scale: float = 0.6,
) -> PopulationDLSTM:
    """A model whose weights (including biases) are all random, not the structured init."""
    model = PopulationDLSTM(P, input_size, hidden, layers, out, seed=seed, dtype=dtype, backend=backend)
    gen = torch.Generator().manual_seed(1000 + seed)
    model.load_flat(torch.randn(P, model.num_params, generator=gen, dtype=dtype) * scale)
    return model


def reference(model: PopulationDLSTM, k: int, x: torch.Tensor, state=None):
    """Individual k through torch.nn.LSTM + nn.Linear (state in our (P, B, H) per-layer format)."""
    lstm, head = model.to_torch_lstm(k)
    hx = None
    if state is not None:
        hx = (torch.stack([h[k] for h, _ in state]), torch.stack([c[k] for _, c in state]))
    hs, (h_n, c_n) = lstm(x, hx)
    return head(hs), h_n, c_n


def randn(*shape: int, seed: int = 0, dtype: torch.dtype = F64) -> torch.Tensor:
    return torch.randn(*shape, generator=torch.Generator().manual_seed(seed), dtype=dtype)


# ------------------------------------------------------------------------------------ layout


def test_paper_configuration_parameter_count() -> None:
    # torch.nn.LSTM + Linear of the same size, minus torch's second bias (the paper has one per gate).
    lstm, head = torch.nn.LSTM(1, 10, 2), torch.nn.Linear(10, 1)
    torch_count = sum(p.numel() for p in [*lstm.parameters(), *head.parameters()])
    expected = torch_count - 2 * 4 * 10
    assert expected == 1331
    assert LstmShape(1).num_params == expected
    assert PopulationDLSTM(10, 1, seed=0).flatten().shape == (10, expected)
    assert GATE_ORDER == ("i", "f", "g", "o")


def test_flat_layout_is_documented_concatenation() -> None:
    model = random_model(P=2, input_size=3, hidden=4, layers=3, out=2)
    theta = model.flatten()
    for k in range(2):
        ind = model.individual(k)
        names = [f"{p}{layer}" for layer in range(3) for p in ("w_x", "w_h", "b")] + ["w_out", "b_out"]
        assert list(ind) == names
        torch.testing.assert_close(theta[k], torch.cat([ind[n].reshape(-1) for n in names]), rtol=0, atol=0)
    # gate block g of layer 0 is rows 2H..3H of w_x0: the first flat entries are w_x0 row-major
    torch.testing.assert_close(theta[:, :12].reshape(2, 4, 3), model.w_x0.detach()[:, :4], rtol=0, atol=0)


def test_flatten_load_flat_round_trip_and_forward_flat() -> None:
    a = random_model(seed=1)
    b = random_model(seed=2)
    assert not torch.equal(a.flatten(), b.flatten())
    b.load_flat(a.flatten())
    assert torch.equal(a.flatten(), b.flatten())
    for pa, pb in zip(a.param_list(), b.param_list(), strict=True):
        assert torch.equal(pa, pb)

    x = randn(2, 25, 2, seed=3)
    y, _ = a(x)
    y_flat, _ = a.forward_flat(a.flatten(), x)
    torch.testing.assert_close(y_flat, y, rtol=0, atol=1e-13)

    # A candidate population of another size, evaluated without touching the module.
    before = a.flatten()
    candidates = randn(5, a.num_params, seed=4) * 0.5
    y_cand, _ = a.forward_flat(candidates, x)
    assert torch.equal(a.flatten(), before)
    c = PopulationDLSTM(5, 2, 5, 2, 2, seed=9, dtype=F64)
    c.load_flat(candidates)
    torch.testing.assert_close(y_cand, c(x)[0], rtol=0, atol=1e-13)
    for k in range(5):
        torch.testing.assert_close(y_cand[k], reference(c, k, x)[0], rtol=0, atol=1e-12)

    with pytest.raises(ValueError, match="rows"):
        a.load_flat(candidates)
    with pytest.raises(ValueError, match=r"\(P, "):
        split_flat(candidates[:, :-1], a.spec)


def test_individual_extraction_round_trip() -> None:
    model = random_model(P=4)
    individuals = [model.individual(k) for k in range(4)]
    assert all(t.dim() >= 1 and t.grad_fn is None for t in individuals[0].values())
    again = PopulationDLSTM.from_individuals(individuals)
    assert again.spec == model.spec and again.w_x0.dtype == F64
    assert torch.equal(again.flatten(), model.flatten())
    subset = PopulationDLSTM.from_individuals([individuals[2]])
    assert torch.equal(subset.flatten()[0], model.flatten()[2])
    individuals[1].pop("w_h1")
    with pytest.raises(ValueError, match="w_h1"):
        PopulationDLSTM.from_individuals(individuals)


# ------------------------------------------------------------------------------------ forward


@pytest.mark.parametrize("backend", ["packed", "loop"])
@pytest.mark.parametrize("shared_input", [True, False])
def test_forward_equals_torch_lstm(backend: str, shared_input: bool) -> None:
    model = random_model(P=3, backend=backend)
    x = randn(2, 30, 2, seed=5) if shared_input else randn(3, 2, 30, 2, seed=5)
    state = tuple((randn(3, 2, 5, seed=10 + i), randn(3, 2, 5, seed=20 + i)) for i in range(2))
    for given_state in (None, state):
        y, final = model(x, given_state)
        assert y.shape == (3, 2, 30, 2)
        for k in range(3):
            y_ref, h_n, c_n = reference(model, k, x if shared_input else x[k], given_state)
            torch.testing.assert_close(y[k], y_ref, rtol=0, atol=1e-12)
            for layer in range(2):
                torch.testing.assert_close(final[layer][0][k], h_n[layer], rtol=0, atol=1e-12)
                torch.testing.assert_close(final[layer][1][k], c_n[layer], rtol=0, atol=1e-12)


def test_float32_fast_path_equals_torch_lstm() -> None:
    # float32 takes torch's oneDNN kernel for the packed population: check it, values and gradients.
    model = random_model(P=4, input_size=1, hidden=10, out=1, dtype=torch.float32, scale=0.3)
    x = randn(1, 200, 1, seed=6, dtype=torch.float32)
    y, _ = model(x)
    y.square().sum().backward()
    for k in range(4):
        lstm, head = model.to_torch_lstm(k)
        y_ref = head(lstm(x)[0])
        torch.testing.assert_close(y[k], y_ref, rtol=1e-5, atol=1e-5)
        y_ref.square().sum().backward()
        torch.testing.assert_close(model.w_h1.grad[k], lstm.weight_hh_l1.grad, rtol=1e-4, atol=1e-5)
        torch.testing.assert_close(model.b0.grad[k], lstm.bias_ih_l0.grad, rtol=1e-4, atol=1e-5)


@pytest.mark.parametrize("backend", ["packed", "loop"])
def test_gradients_equal_torch_lstm(backend: str) -> None:
    model = random_model(P=3, backend=backend)
    x, target = randn(2, 20, 2, seed=7), randn(2, 20, 2, seed=8)
    y, _ = model(x)
    per_individual_loss(y, target).sum().backward()
    for k in range(3):
        lstm, head = model.to_torch_lstm(k)
        per_individual_loss(head(lstm(x)[0]).unsqueeze(0), target).sum().backward()
        for layer in range(2):
            torch.testing.assert_close(
                getattr(model, f"w_x{layer}").grad[k], getattr(lstm, f"weight_ih_l{layer}").grad
            )
            torch.testing.assert_close(
                getattr(model, f"w_h{layer}").grad[k], getattr(lstm, f"weight_hh_l{layer}").grad
            )
            torch.testing.assert_close(
                getattr(model, f"b{layer}").grad[k], getattr(lstm, f"bias_ih_l{layer}").grad
            )
        torch.testing.assert_close(model.w_out.grad[k], head.weight.grad)
        torch.testing.assert_close(model.b_out.grad[k], head.bias.grad)


def test_step_loop_equals_forward_and_streaming_resumes() -> None:
    model = random_model(P=3)
    x = randn(3, 2, 40, 2, seed=9)
    y, final = model(x)
    state = None
    for t in range(40):
        y_t, state = model.step(x[:, :, t], state)
        torch.testing.assert_close(y_t, y[:, :, t], rtol=0, atol=1e-12)
    for (h, c), (h_ref, c_ref) in zip(state, final, strict=True):
        torch.testing.assert_close(h, h_ref, rtol=0, atol=1e-12)
        torch.testing.assert_close(c, c_ref, rtol=0, atol=1e-12)
    # Chunked sequence with the state carried over == one pass.
    y1, s1 = model(x[:, :, :17])
    y2, _ = model(x[:, :, 17:], s1)
    torch.testing.assert_close(torch.cat([y1, y2], dim=2), y, rtol=0, atol=1e-12)
    # A shared input (B, in) is broadcast to every individual.
    y_shared, _ = model.step(x[0, :, 0])
    y_expanded, _ = model.step(x[0, :, 0].expand(3, 2, 2))
    assert torch.equal(y_shared, y_expanded)


@settings(max_examples=12, deadline=None)
@given(
    P=st.integers(1, 5),
    B=st.integers(1, 3),
    T=st.integers(1, 12),
    input_size=st.integers(1, 3),
    hidden=st.integers(1, 6),
    layers=st.integers(1, 3),
    out=st.integers(1, 3),
    group_size=st.integers(1, 4),
    shared=st.booleans(),
)
def test_packed_groups_equal_reference_loop(
    P: int, B: int, T: int, input_size: int, hidden: int, layers: int, out: int, group_size: int, shared: bool
) -> None:
    model = random_model(P, input_size, hidden, layers, out, seed=P + T)
    x = randn(B, T, input_size, seed=T) if shared else randn(P, B, T, input_size, seed=T)
    packed, packed_state = forward_flat(model.flatten(), x, model.spec, group_size=group_size)
    loop, loop_state = forward_flat(model.flatten(), x, model.spec, backend="loop")
    torch.testing.assert_close(packed, loop, rtol=0, atol=1e-12)
    for a, b in zip(packed_state, loop_state, strict=True):
        torch.testing.assert_close(a[0], b[0], rtol=0, atol=1e-12)
        torch.testing.assert_close(a[1], b[1], rtol=0, atol=1e-12)


def test_input_validation() -> None:
    model = random_model(P=3)
    with pytest.raises(ValueError, match="in=2"):
        model(randn(2, 5, 3))
    with pytest.raises(ValueError, match="population dim 4"):
        model(randn(4, 2, 5, 2))
    with pytest.raises(ValueError, match="dtype"):
        model(randn(2, 5, 2, dtype=torch.float32))
    with pytest.raises(ValueError, match="state"):
        model(randn(2, 5, 2), ((torch.zeros(3, 2, 5), torch.zeros(3, 2, 5)),))


# ------------------------------------------------------------------------------------ isolation


def test_nonfinite_individual_does_not_leak_into_others() -> None:
    model = random_model(P=4)
    x, target = randn(2, 30, 2, seed=11), randn(2, 30, 2, seed=12)
    clean = model(x)[0].detach()
    with torch.no_grad():
        model.w_h0[1, 3, 2] = float("nan")
        model.b1[2, 0] = float("inf")
    y, _ = model(x)
    assert torch.isnan(y[1]).all() and torch.isnan(y[2]).all()
    torch.testing.assert_close(y[[0, 3]], clean[[0, 3]], rtol=0, atol=1e-12)
    fitness = population_loss(model, x, target)
    assert torch.isnan(fitness[[1, 2]]).all() and torch.isfinite(fitness[[0, 3]]).all()
    per_individual_loss(y, target)[[0, 3]].sum().backward()
    assert torch.isfinite(model.w_h0.grad[[0, 3]]).all()


def test_nan_inside_packed_call_falls_back_to_one_call_per_individual(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # Finite weights can still overflow to inf - inf inside one individual (whether they do depends
    # on the BLAS kernel's FMA use), and the packed matmul would spread that NaN as 0 * NaN. Inject
    # exactly that: any packed call over more than one individual comes back contaminated.
    model = random_model(P=3, hidden=5)
    x = randn(1, 10, 2, seed=13)
    clean = model(x)[0].detach()
    real_lstm = torch.lstm
    hidden_sizes: list[int] = []

    def contaminating_lstm(inp, hx, params, *args):
        out, h_n, c_n = real_lstm(inp, hx, params, *args)
        hidden_sizes.append(out.shape[-1])
        if out.shape[-1] > 5:
            out = out * float("nan")
        return out, h_n, c_n

    monkeypatch.setattr(torch, "lstm", contaminating_lstm)
    y, _ = model(x)
    assert hidden_sizes == [15, 5, 5, 5]
    torch.testing.assert_close(y, clean, rtol=0, atol=1e-12)


# ------------------------------------------------------------------------------------ init


def test_initialisation_is_seeded_and_per_individual() -> None:
    a = PopulationDLSTM(5, 1, seed=42)
    assert torch.equal(a.flatten(), PopulationDLSTM(5, 1, seed=42).flatten())
    assert not torch.equal(a.flatten(), PopulationDLSTM(5, 1, seed=43).flatten())
    # Individual k depends on (seed, k) only: a larger population extends a smaller one.
    assert torch.equal(PopulationDLSTM(3, 1, seed=42).flatten(), a.flatten()[:3])
    assert len({tuple(row.tolist()) for row in a.flatten()}) == 5
    # float64 and float32 models from one seed hold the same weights (up to rounding).
    b = PopulationDLSTM(5, 1, seed=42, dtype=F64)
    torch.testing.assert_close(b.flatten().float(), a.flatten(), rtol=0, atol=0)


def test_matlab_initialisation_properties() -> None:
    model = PopulationDLSTM(3, 2, hidden_size=6, seed=0, dtype=F64)
    H = 6
    for k in range(3):
        ind = model.individual(k)
        for layer in range(2):
            w_h = ind[f"w_h{layer}"]
            torch.testing.assert_close(w_h.T @ w_h, torch.eye(H, dtype=F64))  # orthogonal columns
            expected_bias = torch.zeros(4 * H, dtype=F64)
            expected_bias[H : 2 * H] = 1.0  # unit forget-gate bias (gate order i, f, g, o)
            assert torch.equal(ind[f"b{layer}"], expected_bias)
            n_in = 2 if layer == 0 else H
            assert ind[f"w_x{layer}"].abs().max() <= math.sqrt(6 / (n_in + 4 * H))
        assert torch.equal(ind["b_out"], torch.zeros(1, dtype=F64))


# ------------------------------------------------------------------------------------ training


def drift_curve(n: int) -> torch.Tensor:
    """A smooth warm-up-like drift (exponential settling plus a slow ramp), scaled to ~[-1, 1]."""
    t = torch.linspace(0.0, 1.0, n, dtype=F64)
    u = 1.0 - torch.exp(-t / 0.25) + 0.3 * t + 0.05 * torch.sin(12.0 * t)
    return 2.0 * (u - u.min()) / (u.max() - u.min()) - 1.0


def test_one_step_ahead_pairs() -> None:
    u = torch.arange(6.0)
    inputs, targets = one_step_ahead(u)
    assert inputs.shape == targets.shape == (1, 5, 1)
    assert torch.equal(inputs[0, :, 0], u[:-1]) and torch.equal(targets[0, :, 0], u[1:])
    with pytest.raises(ValueError):
        one_step_ahead(torch.zeros(1))


@pytest.mark.parametrize("grad_clip", [None, 0.05])
def test_population_training_equals_training_each_individual_alone(grad_clip: float | None) -> None:
    inputs, targets = one_step_ahead(drift_curve(60))
    population = PopulationDLSTM(3, 1, hidden_size=6, seed=5, dtype=F64)
    initial = [population.individual(k) for k in range(3)]
    history = train_population(
        population, inputs, targets, lr=0.02, iterations=12, grad_clip=grad_clip, progress=False
    )
    assert history.losses.shape == (12, 3)
    for k in range(3):
        alone = PopulationDLSTM.from_individuals([initial[k]])
        alone_history = train_population(
            alone, inputs, targets, lr=0.02, iterations=12, grad_clip=grad_clip, progress=False
        )
        torch.testing.assert_close(alone.flatten()[0], population.flatten()[k], rtol=0, atol=1e-10)
        torch.testing.assert_close(alone_history.losses[:, 0], history.losses[:, k], rtol=0, atol=1e-12)


def test_per_individual_clipping_bounds_each_norm() -> None:
    model = random_model(P=3)
    x, target = randn(1, 15, 2, seed=14), randn(1, 15, 2, seed=15) * 10
    per_individual_loss(model(x)[0], target).sum().backward()

    def norms() -> torch.Tensor:
        return torch.stack([p.grad.reshape(3, -1).square().sum(1) for p in model.param_list()]).sum(0).sqrt()

    before = norms()
    limit = float(before.median())
    clip_per_individual(model.param_list(), limit)
    after = norms()
    torch.testing.assert_close(
        after, torch.minimum(before, torch.tensor(limit, dtype=F64)), rtol=1e-6, atol=0
    )


def test_training_reduces_every_individuals_loss() -> None:
    inputs, targets = one_step_ahead(drift_curve(300).float())
    model = PopulationDLSTM(4, 1, seed=7)
    start = population_loss(model, inputs, targets)
    history = train_population(model, inputs, targets, iterations=60, progress=False)
    # no-grad (fitness) and training forwards use different oneDNN primitives: equal to rounding
    torch.testing.assert_close(history.losses[0], start.double(), rtol=1e-5, atol=0)
    assert (history.final_loss < 0.2 * start.double()).all(), (start, history.final_loss)
    torch.testing.assert_close(history.final_loss, population_loss(model, inputs, targets).double())
    assert history.iterations == 60 and not history.stopped_early
    assert history.best() == int(history.final_loss.argmin())


def test_training_is_deterministic_per_seed() -> None:
    inputs, targets = one_step_ahead(drift_curve(200).float())

    def run(seed: int) -> tuple[torch.Tensor, torch.Tensor]:
        model = PopulationDLSTM(3, 1, seed=seed)
        history = train_population(model, inputs, targets, iterations=15, seed=seed, progress=False)
        return model.flatten(), history.losses

    theta_a, losses_a = run(1)
    theta_b, losses_b = run(1)
    assert torch.equal(theta_a, theta_b) and torch.equal(losses_a, losses_b)
    assert not torch.equal(theta_a, run(2)[0])


def test_callback_stops_training() -> None:
    inputs, targets = one_step_ahead(drift_curve(50).float())
    model = PopulationDLSTM(2, 1, seed=0)
    seen: list[int] = []

    def stop_at_third(iteration: int, losses: torch.Tensor) -> bool:
        assert losses.shape == (2,)
        seen.append(iteration)
        return iteration == 2

    history = train_population(model, inputs, targets, iterations=50, progress=False, callback=stop_at_third)
    assert seen == [0, 1, 2] and history.iterations == 3 and history.stopped_early
    with pytest.raises(ValueError, match="NaN"):
        train_population(model, inputs, targets * float("nan"), iterations=1, progress=False)


def test_population_loss_from_theta_matches_module() -> None:
    model = random_model(P=3)
    x, target = randn(2, 12, 2, seed=16), randn(2, 12, 2, seed=17)
    from_module = population_loss(model, x, target)
    from_theta = population_loss(model.flatten(), x, target, spec=model.spec)
    torch.testing.assert_close(from_theta, from_module, rtol=0, atol=1e-14)
    by_hand = torch.stack([(reference(model, k, x)[0] - target).square().mean() for k in range(3)])
    torch.testing.assert_close(from_module, by_hand, rtol=0, atol=1e-12)
    with pytest.raises(ValueError, match="spec"):
        population_loss(model.flatten(), x, target)
