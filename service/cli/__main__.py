"""``python -m service.cli``: the ``depict`` command."""

from service.cli import run

run()
