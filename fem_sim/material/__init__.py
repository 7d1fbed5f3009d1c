"""Material laws: the uncoupled Ogden model (numpy reference and compiled kernel)."""
