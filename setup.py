"""The compiled kernels of fem_squeal, built with the package (``pip install``, and ``pip install -e``
builds them in place): C sources in ``fem_squeal/fe/kernels``, plain shared libraries that the
package loads with ctypes (:func:`fem_squeal.util.native.built_library`).  Nothing is compiled at
run time.  Each is optional: where one cannot be built (no C compiler, no CHOLMOD headers) the
installation goes on without it and the package takes the library path it replaces (PETSc's
product, dolfinx's assembly, PETSc's CHOLMOD or MUMPS); ``results.json`` says which path ran.

Headers and libraries: Debian's ``libsuitesparse-dev`` (cholmod.h, -lcholmod), found through
``SUITESPARSE_INCLUDE`` or the usual folders."""
from __future__ import annotations

import os

from setuptools import Extension, setup

SUITESPARSE = [d for d in (os.environ.get("SUITESPARSE_INCLUDE", ""), "/usr/include/suitesparse",
                           "/usr/local/include/suitesparse") if d and os.path.isfile(os.path.join(d, "cholmod.h"))]
KERNELS = "fem_squeal/fe/kernels"


def kernel(name: str, sources: list[str], opt: str = "-O3", **kw) -> Extension:
    return Extension(f"fem_squeal.fe.kernels.{name}", [f"{KERNELS}/{s}" for s in sources], optional=True,
                     extra_compile_args=[opt], **kw)


ext_modules = [
    kernel("csr_block", ["csr_block.c"]),
    kernel("cell_assembly", ["cell_assembly.c"], "-O2"),
    kernel("supernodal_solve", ["supernodal_solve.c"], depends=[f"{KERNELS}/supernodal_kernel.h"]),
    kernel("substructure", ["substructure.c"]),
]
if SUITESPARSE:
    ext_modules.append(kernel("cholmod_shim", ["cholmod_shim.c"], "-O2", include_dirs=SUITESPARSE[:1],
                              libraries=["cholmod"]))

setup(ext_modules=ext_modules)
