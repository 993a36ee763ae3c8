"""The consistency tests' shared graphs (``consistency_graphs``) for the engines' tests."""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parents[1]))
