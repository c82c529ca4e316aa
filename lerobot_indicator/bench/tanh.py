"""Forward + backward of the policy's 3x256 tanh MLPs with ``torch.tanh`` and with the CPU tanh formulas.

Candidates: ``torch.tanh``; 2 sigmoid(2x) - 1 with torch's ``tanh_backward`` (eager); Eigen's clamped
rational approximation (eager and under ``torch.compile``, where Inductor fuses it into one kernel). Arms:
one MLP of the critic's shape (input obs + goal + action, three hidden layers of 256, one output) and the
activation alone on a (batch, 256) layer, at the trainer's batch sizes. Arms run in interleaved rounds,
timed in thread CPU time and wall-clock; the per-round ratio to ``torch.tanh`` (same arm kind, executor and
batch) is reported.
"""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable

import torch
from torch import Tensor, nn


class SigmoidTanh(torch.autograd.Function):
    """tanh(x) = 2 sigmoid(2x) - 1 (max abs error 2e-7), gradient by torch's ``tanh_backward``."""

    @staticmethod
    def forward(ctx, x: Tensor) -> Tensor:
        y = torch.sigmoid(x * 2).mul_(2).sub_(1)
        ctx.save_for_backward(y)
        return y

    @staticmethod
    def backward(ctx, grad: Tensor) -> Tensor:
        (y,) = ctx.saved_tensors
        return torch.ops.aten.tanh_backward(grad, y)


# Eigen's float tanh: odd numerator and even denominator coefficients (in x^2), lowest order first.
TANH_NUM = (
    4.89352455891786e-03,
    6.37261928875436e-04,
    1.48572235717979e-05,
    5.12229709037114e-08,
    -8.60467152213735e-11,
    2.00018790482477e-13,
    -2.76076847742355e-16,
)
TANH_DEN = (4.89352518554385e-03, 2.26843463243900e-03, 1.18534705686654e-04, 1.19825839466702e-06)
TANH_CLAMP = 7.90531110763549805


class RationalTanh(torch.autograd.Function):
    """tanh(x) ~= x p(x^2) / q(x^2) on [-7.9, 7.9], +-1 beyond (max abs error 4e-7); out of place."""

    @staticmethod
    def forward(ctx, x: Tensor) -> Tensor:
        x = x.clamp(-TANH_CLAMP, TANH_CLAMP)
        x2 = x * x
        p = x2 * TANH_NUM[6] + TANH_NUM[5]
        for a in TANH_NUM[4::-1]:
            p = p * x2 + a
        q = x2 * TANH_DEN[3] + TANH_DEN[2]
        for b in TANH_DEN[1::-1]:
            q = q * x2 + b
        y = x * p / q
        ctx.save_for_backward(y)
        return y

    @staticmethod
    def backward(ctx, grad: Tensor) -> Tensor:
        (y,) = ctx.saved_tensors
        return grad * (1 - y * y)


ACTIVATIONS: dict[str, Callable[[Tensor], Tensor]] = {
    "torch_tanh": torch.tanh,
    "sigmoid_tanh": SigmoidTanh.apply,
    "rational_tanh": RationalTanh.apply,
}
# (activation, compiled): torch.tanh against each formula in the executor it was written for.
ARMS = [("torch_tanh", False), ("sigmoid_tanh", False), ("rational_tanh", False)]
COMPILED_ARMS = [("torch_tanh", True), ("rational_tanh", True)]


class Activation(nn.Module):
    def __init__(self, fn: Callable[[Tensor], Tensor]):
        super().__init__()
        self.fn = fn

    def forward(self, x: Tensor) -> Tensor:
        return self.fn(x)


def tanh_mlp(activation: str, in_dim: int = 9, hidden: int = 256, layers: int = 3) -> nn.Sequential:
    """The critic's MLP (state reach: 3-d observation, 3-d goal, 3-d action) with the given tanh."""
    torch.manual_seed(0)
    modules: list[nn.Module] = []
    for _ in range(layers):
        modules += [nn.Linear(in_dim, hidden), Activation(ACTIVATIONS[activation])]
        in_dim = hidden
    modules.append(nn.Linear(in_dim, 1))
    return nn.Sequential(*modules)


def mlp_step(activation: str, batch_size: int, compiled: bool) -> Callable[[], None]:
    """One forward + backward of ``tanh_mlp`` on a fixed random batch (gradients cleared each call)."""
    net = tanh_mlp(activation)
    x = torch.randn(batch_size, net[0].in_features, generator=torch.Generator().manual_seed(1))

    def loss() -> Tensor:
        return net(x).square().mean()

    fn = torch.compile(loss, dynamic=False) if compiled else loss

    def step() -> None:
        net.zero_grad(set_to_none=True)
        fn().backward()

    return step


def op_step(activation: str, batch_size: int, hidden: int = 256) -> Callable[[], None]:
    """The activation alone, forward + backward, on one hidden layer's pre-activations (eager)."""
    x = torch.randn(batch_size, hidden, generator=torch.Generator().manual_seed(1)).requires_grad_()
    grad = torch.ones(batch_size, hidden)
    fn = ACTIVATIONS[activation]

    def step() -> None:
        torch.autograd.grad(fn(x), x, grad)

    return step


def arm_name(kind: str, activation: str, compiled: bool, batch_size: int) -> str:
    return f"{kind}_{activation}{'_compiled' if compiled else ''}_b{batch_size}"


def make_arms(batch_sizes: list[int], compiled: bool) -> dict[str, tuple[tuple, Callable[[], None]]]:
    """name -> ((kind, activation, compiled, batch size), step)."""
    arms = {}
    for b in batch_sizes:
        for activation, is_compiled in ARMS + (COMPILED_ARMS if compiled else []):
            key = ("mlp", activation, is_compiled, b)
            arms[arm_name(*key)] = (key, mlp_step(activation, b, is_compiled))
        for activation, _ in ARMS:
            key = ("op", activation, False, b)
            arms[arm_name(*key)] = (key, op_step(activation, b))
    return arms


def interleaved_cpu_times(
    steps: dict[str, Callable[[], None]], calls: int, rounds: int, warmup: int = 3
) -> dict[str, dict[str, list[float]]]:
    """Per arm and round: thread CPU seconds and wall seconds of ``calls`` calls, arms interleaved.

    Thread CPU time counts only the cycles this thread ran, so other jobs on a shared machine change it
    far less than wall-clock (through caches and frequency, not through waiting); torch must run on this
    thread (one intra-op thread)."""
    for step in steps.values():
        for _ in range(warmup):
            step()
    out = {name: {"cpu_s": [], "wall_s": []} for name in steps}
    names = list(steps)
    for r in range(rounds):
        k = r % len(names)
        for name in names[k:] + names[:k]:  # the order rotates, so no arm always follows the same one
            step = steps[name]
            c0, w0 = time.thread_time(), time.perf_counter()
            for _ in range(calls):
                step()
            out[name]["cpu_s"].append(time.thread_time() - c0)
            out[name]["wall_s"].append(time.perf_counter() - w0)
    return out


def bench_tanh(batch_sizes: list[int], calls: int, rounds: int, compiled: bool = True) -> dict[str, object]:
    """Calls per CPU second of every arm (median over rounds) and each formula's speed-up over torch.tanh in
    the same kind of arm, executor and batch: the median (and range) of the per-round ratios, in CPU time and
    in wall-clock."""
    if torch.get_num_threads() != 1:
        raise ValueError(
            f"bench_tanh times one thread: torch.set_num_threads(1), got {torch.get_num_threads()}"
        )
    arms = make_arms(batch_sizes, compiled)
    times = interleaved_cpu_times({name: step for name, (_, step) in arms.items()}, calls, rounds)
    rates = {
        name: {
            "calls_per_cpu_s": calls / statistics.median(t["cpu_s"]),
            "calls_per_wall_s": calls / statistics.median(t["wall_s"]),
            "rounds_cpu_s": t["cpu_s"],
            "rounds_wall_s": t["wall_s"],
        }
        for name, t in times.items()
    }
    speedups = {}
    for name, ((kind, activation, is_compiled, b), _) in arms.items():
        if activation == "torch_tanh":
            continue
        base = times[arm_name(kind, "torch_tanh", is_compiled, b)]
        entry = {}
        for clock in ("cpu_s", "wall_s"):
            ratios = sorted(t / x for t, x in zip(base[clock], times[name][clock], strict=True))
            entry[clock.removesuffix("_s")] = {
                "median": statistics.median(ratios),
                "min": ratios[0],
                "max": ratios[-1],
            }
        speedups[f"{name}_over_torch_tanh"] = entry
    return {"rates": rates, "speedup": speedups}


def max_errors(n: int = 40001) -> dict[str, float]:
    """Max abs error of each formula against float64 tanh on [-20, 20] (value and gradient)."""
    x = torch.linspace(-20, 20, n).requires_grad_()
    exact = torch.tanh(x.detach().double())
    out = {}
    for name, fn in ACTIVATIONS.items():
        y = fn(x)
        (grad,) = torch.autograd.grad(y, x, torch.ones_like(y))
        out[name] = float((y.detach().double() - exact).abs().max())
        out[f"{name}_grad"] = float((grad.double() - (1 - exact**2)).abs().max())
    return out
