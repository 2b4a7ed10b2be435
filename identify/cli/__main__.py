"""``python -m itr_identify.cli ARGS``: the ``itr`` command."""

import sys

from .dispatch import main

sys.exit(main())
