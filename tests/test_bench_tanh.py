"""The CPU tanh benchmark: its candidate formulas are tanh to float precision, and its ratios compare like
with like."""

import pytest
import torch

from lerobot_indicator.bench import tanh as bench


@pytest.mark.parametrize(("name", "atol"), [("sigmoid_tanh", 3e-7), ("rational_tanh", 5e-7)])
def test_candidates_match_torch_tanh_and_its_gradient(name, atol):
    fn = bench.ACTIVATIONS[name]
    x = torch.cat([torch.linspace(-20, 20, 4001), torch.tensor([0.0, 1e-30, -1e-30])]).requires_grad_()
    y = fn(x)
    exact = torch.tanh(x.detach().double())
    torch.testing.assert_close(y.double(), exact, atol=atol, rtol=0)
    assert y.abs().max() <= 1.0
    (grad,) = torch.autograd.grad(y, x, torch.ones_like(y))
    torch.testing.assert_close(grad.double(), 1 - exact**2, atol=1e-6, rtol=0)


def test_every_formula_is_compared_with_torch_tanh_in_the_same_arm(monkeypatch):
    monkeypatch.setattr(torch, "get_num_threads", lambda: 1)
    result = bench.bench_tanh([4], calls=1, rounds=2, compiled=False)
    assert set(result["speedup"]) == {
        f"{kind}_{name}_b4_over_torch_tanh"
        for kind in ("mlp", "op")
        for name in ("sigmoid_tanh", "rational_tanh")
    }
    rates = result["rates"]
    for name, rate in rates.items():
        assert len(rate["rounds_cpu_s"]) == 2 and rate["calls_per_cpu_s"] > 0, name
    base, arm = rates["mlp_torch_tanh_b4"]["rounds_cpu_s"], rates["mlp_sigmoid_tanh_b4"]["rounds_cpu_s"]
    ratios = sorted(b / a for b, a in zip(base, arm, strict=True))
    assert result["speedup"]["mlp_sigmoid_tanh_b4_over_torch_tanh"]["cpu"]["median"] == pytest.approx(
        sum(ratios) / 2
    )
    monkeypatch.setattr(torch, "get_num_threads", lambda: 2)
    with pytest.raises(ValueError, match="one thread"):
        bench.bench_tanh([4], calls=1, rounds=1, compiled=False)
