"""``python -m myoface``: the command-line tool."""

import sys

from myoface.cli import main

sys.exit(main())
