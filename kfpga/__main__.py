"""``python -m kfpga``: the command line."""

import sys

from kfpga.cli import main

sys.exit(main())
