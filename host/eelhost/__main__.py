"""``python -m eelhost``: the ``eelbot`` command line."""

import sys

from eelhost.cli import main

sys.exit(main())
