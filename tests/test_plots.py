"""The learning-curve figure shows every logged series legibly."""

import matplotlib.pyplot as plt

from lerobot_indicator.training.plots import learning_curve_figure


def rows(env_steps):
    return [
        {"env_steps": e, "step": 40 * (i + 1), "eval_success_rate": 0.0, "train_success_rate": 0.0,
         "q_mean": -20.0 + i, "q_target_mean": -20.0 + i, "frac_positive": 0.45, "frac_filtered": 0.0}
        for i, e in enumerate(env_steps)
    ]  # fmt: skip


def test_rates_have_fixed_unit_axes_and_overlapping_series_stay_visible():
    fig = learning_curve_figure(rows([100, 200, 300]))
    success, _, _, q, fractions = fig.axes
    assert success.get_ylim() == (-0.02, 1.02) and fractions.get_ylim() == (
        -0.02,
        1.02,
    )  # all-zero success too
    first, second = q.lines
    assert first.get_linestyle() == "-" and second.get_linestyle() == "--"
    assert first.get_linewidth() > second.get_linewidth()  # q_mean shows around q_target_mean drawn on top
    assert success.get_xlabel() == "environment steps"
    plt.close(fig)


def test_a_run_that_collects_no_episodes_is_plotted_against_optimisation_steps():
    fig = learning_curve_figure(rows([0, 0, 0]))
    assert fig.axes[0].get_xlabel() == "optimisation steps"
    assert list(fig.axes[0].lines[0].get_xdata()) == [40, 80, 120]
    plt.close(fig)
