"""Benchmark helpers: peer implementations (LeRobot's SAC), FLOP counting and machine peak throughput."""
