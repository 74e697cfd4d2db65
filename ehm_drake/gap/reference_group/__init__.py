"""The gap diagnosis against a reference group of subjects."""
