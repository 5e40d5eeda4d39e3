"""``python -m kfpga.cli``: the command line."""

import sys

from kfpga.cli import main

sys.exit(main())
