"""Every error fem_squeal raises, defined once, under one base class.

``FemSquealError`` is what the command line catches: an :class:`InputError` (a scene, a command
line, a mesh file or a model that is refused before or while it is read) exits with 2, a
:class:`StorageError` (a full disk, a folder that cannot be written) with 4, any other
``FemSquealError`` (a computation that failed: a solver that did not converge, a run killed) with 3.
The message always starts with what is wrong (a scene key path, a file, a stage).  The classes keep
the builtin base they had (``ValueError``, ``KeyError``, ``RuntimeError``) so ``except ValueError``
in user scripts still works.
"""
from __future__ import annotations


class FemSquealError(Exception):
    """Base class of every error of the package."""

    exit_code = 3

    def __str__(self) -> str:                       # KeyError would quote the message
        return BaseException.__str__(self)


class InputError(FemSquealError, ValueError):
    """Bad input: the message names the field (key path, file, option) and the reason."""

    exit_code = 2


class SceneError(InputError):
    """Invalid scene: the message starts with the key path."""


class MeshError(InputError):
    """A mesh file that cannot be read or used (wraps ``geometry.mesh_file.MeshImportError``)."""


class ResourceError(InputError):
    """A model too large for the machines of the run (estimated before anything is built)."""


class ModelError(InputError):
    """A model description the physics refuses (a value out of range, an inconsistent choice)."""


class UnknownNameError(ModelError, KeyError):
    """A name that is not in the model: a face, a part, a parameter (the message lists the known ones)."""


class MatrixFileError(InputError):
    """A matrix file that cannot be read or used (missing, of an unknown format, not square, of the
    wrong size, complex): the message starts with the file."""


class ExpressionError(InputError):
    """An operator expression of named matrices and parameters that is refused (it is parsed, never
    evaluated as Python).  ``kind`` names the reason: ``syntax``, ``attribute``, ``subscript``,
    ``call``, ``name``, ``operator``, ``construct``, ``matrix_product``, ``matrix_denominator``,
    ``matrix_power``, ``matrix_argument``, ``matrix_plus_number``, ``number``, ``no_matrix``."""

    def __init__(self, message: str, kind: str = ""):
        super().__init__(message)
        self.kind = kind


class PipelineError(FemSquealError, RuntimeError):
    """The stage cache or the pipeline refused a run (a stage that cannot be computed, a locked entry)."""

    exit_code = 2


class StorageError(FemSquealError, OSError):
    """A file the run must write could not be: no space left, a quota, a read-only folder, no
    permission (exit 4).  The message names the path and the reason and, when known, the bytes needed
    and free; nothing half-written is left behind and no earlier output is changed."""

    exit_code = 4


class SolveError(FemSquealError, RuntimeError):
    """A computation that failed (exit 3); the message names the stage and the reason."""


class MeshingError(SolveError):
    """The geometry could not be built or meshed (a gmsh builder failed on valid input)."""


class EigenSolveError(SolveError):
    """An eigensolve that did not converge or returned pairs with too large residuals."""


class PreloadError(SolveError):
    """The nonlinear static preload did not converge."""


class ReductionError(SolveError):
    """The reduced basis did not reach its accuracy target."""


class MasaError(SolveError):
    """Modal amplitude stability analysis failed or was given a model it cannot treat."""


class TransientError(SolveError):
    """The nonlinear transient failed (Newton did not converge, a bad state)."""
