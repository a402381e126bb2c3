"""``mavins review``: a Rerun recording rendered to PNG."""

from __future__ import annotations

import argparse


def _add_review(sub: argparse._SubParsersAction) -> None:
    from ..record.review import DESCRIPTION, add_arguments, run

    p = sub.add_parser("review", help="render a Rerun recording to PNG, headless", description=DESCRIPTION)
    add_arguments(p)
    p.set_defaults(func=lambda a: run(a, "mavins review"))
