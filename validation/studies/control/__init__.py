"""Adaptive shift control (the adaptive-control issue), by concern:

* :mod:`.controller`: the TCU's clutch-to-clutch shift controller (fill, torque phase, inertia
  phase with feed-forward from the shift model and PI feedback on slip, lock-up);
* :mod:`.closed_loop`: one shift in closed loop: the truth's hybrid simulation stepped from TCU
  tick to tick through each element's actuator (:mod:`gearsym.validation.sim.actuator`);
* :mod:`.strategies`: what the controller is told before each shift and what it learns after
  it: fixed calibration, rule-based adaptation, estimator-based, oracle;
* :mod:`.study`: each vehicle of a fleet shifting the same shift ``n`` times per strategy;
* :mod:`.quality`: the shift-quality metrics of one simulated shift (ISO 2631-1 weighted
  acceleration and vibration dose value, peak jerk, inertia-phase duration, flare, tie-up,
  friction energy) and the convergence of a strategy over a sequence of shifts.
"""
