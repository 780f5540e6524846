"""Public path of the friction laws, kept for existing scripts: they live in
:mod:`fem_squeal.reduced.laws.friction`."""
from fem_squeal.reduced.laws.friction import *  # noqa: F403
from fem_squeal.reduced.laws.friction import __all__  # noqa: F401
