"""Studies on the simulated shift: sensitivities, Fisher information, Sobol sweeps, the
estimators and their bounds."""
