"""python -m pyclray: the command line (as the pyclray script)."""
import sys

from .cli import main

sys.exit(main())
