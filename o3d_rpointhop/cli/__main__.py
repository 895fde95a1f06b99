"""``python -m o3d_rpointhop.cli``: the command line."""

import sys

from . import main

sys.exit(main())
