"""Where the repository is, whatever the depth of the test file that asks."""
from __future__ import annotations

from pathlib import Path

#: the repository root (scenes/, demos/, benchmarks/, tests/)
ROOT = Path(__file__).resolve().parents[2]
