"""``python -m fem_squeal``: the command line (:mod:`fem_squeal.app.cli`)."""
import sys

from fem_squeal.app.cli import main

sys.exit(main())
