"""Shared test settings: compiled kernels make the first example slow, so no deadline."""

from hypothesis import settings

settings.register_profile("mavins", deadline=None, max_examples=100)
settings.load_profile("mavins")
