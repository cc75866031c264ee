"""``python3 -m pyfem``: the command line (see `pyfem.cli`)."""
import sys

from pyfem.cli import main

sys.exit(main())
