"""``python -m truestep``: the ``truestep`` command."""

import sys

from truestep.cli import main

sys.exit(main())
