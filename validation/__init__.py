"""Numerical validation of emitted code against the SymPy model."""
