"""``python -m gnssacc``: the ``gnssacc`` command."""
import sys

from .cli import main

sys.exit(main())
