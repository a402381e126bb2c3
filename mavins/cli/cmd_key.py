"""``mavins key``: MAVLink 2 signing keys."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .options import EXIT_USAGE, _subparser


def _add_key(sub: argparse._SubParsersAction) -> None:
    p = _subparser(sub, "key", "make a MAVLink 2 signing key file",
                   "Write a 32-byte signing key (as 64 hex digits, file mode 600). With --passphrase the key is "
                   "SHA-256 of the passphrase, the same key MAVProxy's 'signing setup PASSPHRASE' uses; without, a "
                   "random key.")
    p.add_argument("file", type=Path, metavar="FILE")
    p.add_argument("--passphrase", help="derive the key from a passphrase (MAVProxy's convention)")
    p.add_argument("--force", action="store_true", help="overwrite an existing file")
    p.set_defaults(func=_cmd_key)


def _cmd_key(args: argparse.Namespace) -> int:
    import secrets

    from ..link.signing import key_from_passphrase

    if args.file.exists() and not args.force:
        print(f"mavins key: error: {args.file} exists (use --force to overwrite)", file=sys.stderr)
        return EXIT_USAGE
    try:
        key = key_from_passphrase(args.passphrase) if args.passphrase else secrets.token_bytes(32)
    except UnicodeEncodeError:
        print("mavins key: error: the passphrase must be ASCII (MAVProxy hashes its ASCII bytes)", file=sys.stderr)
        return EXIT_USAGE
    from ..common.files import DataFileError, atomic_output

    if args.file.is_dir():
        print(f"mavins key: error: {args.file} is a directory, expected a file to write", file=sys.stderr)
        return EXIT_USAGE
    try:  # mode 600 from the first byte; renamed into place (an existing key is replaced whole, or kept)
        with atomic_output(args.file, mode=0o600) as tmp, open(tmp, "w", encoding="ascii") as fh:
            fh.write(key.hex() + "\n")
    except (DataFileError, OSError) as exc:
        text = str(exc) if isinstance(exc, DataFileError) else f"{args.file}: cannot write: {exc.strerror or exc}"
        print(f"mavins key: error: {text}", file=sys.stderr)
        return EXIT_USAGE
    print(f"mavins key: wrote {args.file} (mode 600)", file=sys.stderr)
    return 0
