"""Simulation of a shift: scenarios, the reference and hybrid simulations, measured shifts,
and writing the results."""
