"""``python -m pprender``: the command line (:mod:`pprender.cli`)."""

import sys

from .cli import main

sys.exit(main())
