"""What leaves the derivation as files: the generated tree, FMUs and A2L descriptions."""
