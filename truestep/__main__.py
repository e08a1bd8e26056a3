"""``python -m truestep``: the ``truestep`` command."""

import sys

from truestep.command import main

sys.exit(main())
