"""``python -m dyntarget.cli``."""

import sys

from dyntarget.cli import main

sys.exit(main())
