"""``python -m terrapref.cli``: the ``terrapref`` command."""

import sys

from terrapref.cli import main

if __name__ == "__main__":  # not on an import (tests import every module)
    sys.exit(main())
