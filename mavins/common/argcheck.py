"""Option values checked at parse time, shared by the ``mavins`` command line
(mavins/cli/) and the modules that also run on their own (record/review.py).

Light on purpose: ``mavins --help`` imports it.
"""

from __future__ import annotations

import argparse
from typing import Any, Callable


def checked(text: str, parse: Callable[[str], Any], inside: Callable[[Any], bool], expected: str, allowed: str) -> Any:
    """``parse(text)`` when it parses and ``inside`` accepts it; otherwise argparse's usage error naming the value."""
    try:
        v = parse(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected {expected}; got {text!r}") from None
    if not inside(v):
        raise argparse.ArgumentTypeError(f"{text} is outside the allowed range {allowed}")
    return v
