"""``python -m bridge.cli``: the console script without its installed wrapper."""

import sys

from bridge.cli.console import main

sys.exit(main())
