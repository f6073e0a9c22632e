"""``python -m radar_io.cli``: the ``radar-io`` command."""

import sys

from radar_io.cli import main

sys.exit(main())
