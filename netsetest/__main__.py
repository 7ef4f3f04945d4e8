"""``python -m netsetest``: the same as the ``netsetest`` command."""

import sys

from netsetest.cli.main import main

sys.exit(main())
