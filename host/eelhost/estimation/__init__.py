"""Hydrodynamic parameter estimation: fitness, evaluation, optimisers, validation."""
