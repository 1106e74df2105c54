"""The derivation: gearbox description → kinematics → dynamics → analyses (SymPy)."""
