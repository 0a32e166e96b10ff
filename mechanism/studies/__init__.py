"""Studies built on single runs: the paper reproduction (reproduce) and co-simulation step-size studies (stepsize)."""
