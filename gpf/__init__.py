"""Gaussian particle filter hardware: configs, generator, models and testbenches."""
