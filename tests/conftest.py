"""Shared test settings: compiled kernels make the first example slow, so no deadline; tests/ on the
path for the one support module (tests/support.py) and the helpers beside it."""

import sys
from pathlib import Path

from hypothesis import settings

sys.path.insert(0, str(Path(__file__).resolve().parent))

settings.register_profile("mavins", deadline=None, max_examples=100)
settings.load_profile("mavins")
