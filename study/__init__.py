"""Studies of the models: Monte Carlo quality against float64, metrics, plots."""
