"""Fixed-point and float64 reference models."""
