import sys

import jaxfilters  # noqa: F401  (first: importing it sets the XLA:CPU flags, jaxfilters/xla_flags.py)

from benchmarks.run import main  # noqa: E402

sys.exit(main())
