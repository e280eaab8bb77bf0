"""``python -m mipray`` runs ``mipray-record``."""

import sys

from .record import main

sys.exit(main())
