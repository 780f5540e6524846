"""``python -m fem_squeal.cli``: the command line, kept at its public path (it lives in
:mod:`fem_squeal.app.cli`)."""
import sys

from fem_squeal.app.cli import demo_arguments, main

__all__ = ["demo_arguments", "main"]

if __name__ == "__main__":
    sys.exit(main())
