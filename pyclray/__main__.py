"""python -m pyclray: the command line (as the pyclray script)."""
import sys

from .apps.cli import main

sys.exit(main())
