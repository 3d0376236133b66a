"""``python -m service.cli``: the ``depict`` command, ending as Python programs do (so that a
profiler, ``python -m pyinstrument -m service.cli enhance ...``, can write its report; the
``depict`` executable skips the interpreter's teardown, :func:`service.cli.run`)."""

import sys

from service.cli import main

sys.exit(main())
