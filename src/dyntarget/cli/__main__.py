"""``python -m dyntarget.cli``."""

import sys

from dyntarget.cli import main

if __name__ == "__main__":
    sys.exit(main())
