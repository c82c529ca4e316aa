"""Reproduce the paper's comparison (Figure 3 / supplementary ablations) on our tasks, with one command.

Runs ``lerobot-indicator-train`` for every (task, method, seed), resumably (a finished run is skipped,
an interrupted one continues with ``--resume=true``), then aggregates the runs' ``metrics.jsonl`` into
``<out>/summary.json``, learning-curve plots and a markdown table (``benchmarks.experiments.runner``).

    python -m benchmarks.experiments.run --tasks='[reach_state]' --seeds='[0,1,2]' --out=docs/results/experiments \
        --runs_dir=outputs/experiments/runs
    python -m benchmarks.experiments.run --tasks='[reach_state]' --plot_only=true ...   # aggregate only
"""

from benchmarks.experiments.runner import main

if __name__ == "__main__":
    main()
