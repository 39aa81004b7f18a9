"""Allow ``python -m cldet``."""

from cldet.cli import main

main()
