import sys

from dyntarget.cli import main

sys.exit(main())
