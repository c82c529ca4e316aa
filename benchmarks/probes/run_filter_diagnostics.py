"""What reward filtering would discard, per goal source, for a saved online training run.

Section 5.3 of the paper filters R- transitions whose Q(o_t, o_g, a_t) exceeds q0, on the premise that they
are mostly false negatives (the goal *was* reached, within the evaluation epsilon, but not bit for bit). The
trainer logs the filter's overall precision; this script breaks it down by where the goal came from
(o_{t+1}, a future o_{t'}, the recorded goal) and by checkpoint, which is what the training logs cannot show
(``benchmarks.probes.filter_diagnostics``).

For each checkpoint of ``--run_dir`` it rebuilds the replay buffer as it was at that step (the run's
``replay/`` chunks of the cycles before it), draws ``--batches`` batches with the checkpoint's own relabeling
settings, and counts, per source: samples, indicator positives, ground-truth successes, the R- transitions
with Q > q0 (what the filter drops, whether or not the run filtered), and how many of those were ground-truth
successes (the filter's precision). Ground truth is only read here, never by training.

    python -m benchmarks.probes.run_filter_diagnostics --run_dirs='[outputs/rope3/runs/rope_state/indicator/seed_0]' \
        --out=docs/results/experiments_rope/filter_diagnostics.json
"""

import draccus

from benchmarks.probes.filter_diagnostics import FilterDiagnosticsConfig, run

if __name__ == "__main__":
    run(draccus.parse(FilterDiagnosticsConfig))
