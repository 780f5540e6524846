"""``python -m fem_squeal``: the command line (:mod:`fem_squeal.app.cli`)."""
from fem_squeal.app.cli import main

main()
