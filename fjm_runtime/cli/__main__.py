"""``python -m fjm_runtime.cli``: the same as the ``fjm`` command."""

import sys

from .main import main

sys.exit(main())
