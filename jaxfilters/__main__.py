"""`python -m jaxfilters` runs the command line (jaxfilters/cli.py)."""

import sys

from jaxfilters.cli import main

sys.exit(main())
