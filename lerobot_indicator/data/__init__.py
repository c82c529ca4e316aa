"""Recording goal-conditioned LeRobotDatasets from the sim tasks (see docs/dataset_format.md)."""
