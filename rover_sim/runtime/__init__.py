"""The runtime: the runner that drives a world through a scenario's commands, the onboard stack fed observations only,
the evaluator (the one place truth meets the estimates), acceptance (every verdict) and the run's outputs."""
