"""``python -m wbcgrade``: the command line (as the ``wbcgrade`` script)."""

from wbcgrade.cli import main

main()
