"""Online training: episode replay buffer, rollouts, the lerobot-indicator-train loop, plots."""
