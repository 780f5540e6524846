"""Utilities every layer may use (imports nothing else of fem_squeal): atomic writes, progress,
BLAS threads, MPI helpers and the one error base class."""
