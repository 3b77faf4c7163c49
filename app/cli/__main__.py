"""``python -m app.cli``: the same as the ``tactile-zsl`` script."""

import sys

from app.cli import main

sys.exit(main())
