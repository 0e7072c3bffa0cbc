"""Applications that drive a world through the runner: autonav, rock-site surveys, DIMES descents, sweeps."""
