"""Benchmarks, probes and experiments beside the lerobot_indicator package (not installed; run from the
repository root as ``python -m benchmarks.<group>.<cli>``)."""
