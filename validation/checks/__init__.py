"""Checks of the emitted code (C, CasADi, bare-metal) against the SymPy model and the
simulations."""
