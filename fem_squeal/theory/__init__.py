"""Closed-form references (NumPy only): the analytic ring eigenvalues of seed 003."""
