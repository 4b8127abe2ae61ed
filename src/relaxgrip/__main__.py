"""``python -m relaxgrip`` is the ``relaxgrip`` command."""

from relaxgrip.cli import main

main()
