"""Public path of the normal contact laws, kept for existing scripts: they live in
:mod:`fem_squeal.reduced.laws.contact`."""
from fem_squeal.reduced.laws.contact import *  # noqa: F403
from fem_squeal.reduced.laws.contact import __all__  # noqa: F401
