"""Adaptive shift control (issue 29), by concern:

* :mod:`.quality`: the shift-quality metrics of one simulated shift (ISO 2631-1 weighted
  acceleration and vibration dose value, peak jerk, inertia-phase duration, flare, tie-up,
  friction energy) and the convergence of a strategy over a sequence of shifts.
"""
