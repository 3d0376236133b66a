"""``python -m service.cli``: the ``depict`` command."""

import sys

from service.cli import main

sys.exit(main())
