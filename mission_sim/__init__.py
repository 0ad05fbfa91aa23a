"""mission_sim: the world around the link (trajectories, drone power, battery, mission runner, CLI)."""
