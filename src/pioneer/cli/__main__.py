"""``python -m pioneer.cli``: the ``pioneer`` command."""

import sys

from pioneer.cli import main

sys.exit(main())
