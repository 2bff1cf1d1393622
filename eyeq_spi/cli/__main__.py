"""``python -m eyeq_spi.cli``: the ``eyeq-spi`` command."""

import sys

from eyeq_spi.cli import main

sys.exit(main())
