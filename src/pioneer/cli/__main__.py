"""``python -m pioneer.cli``: the ``pioneer`` command."""

import sys

from pioneer.cli import main

if __name__ == "__main__":
    sys.exit(main())
