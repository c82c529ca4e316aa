"""Benchmarks and run diagnostics: peer implementations (LeRobot's SAC, SB3), FLOP counting, machine peak
throughput, the CPU tanh, filter and critic diagnostics of saved runs."""
