"""The finite-element layer (dolfinx, PETSc, SLEPc): UFL forms, model description, assembly,
interface operators, nonlinear preload, eigensolvers, descriptors, projection onto a basis,
penalty diagnostics and field output.  Imports ``util``, ``reduced`` and ``geometry``; never ``app``."""
