"""Simulated laboratories: synthetic data with hidden effects and the blind check."""
