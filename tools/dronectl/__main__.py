"""`python -m dronectl`: the same as the `dronectl` command."""

import sys

from dronectl.cli import main

sys.exit(main())
