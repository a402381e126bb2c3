"""``python -m mavins.cli``: the ``mavins`` console script."""

import sys

from . import main

sys.exit(main())
