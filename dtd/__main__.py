"""``python -m dtd`` is the ``dtd`` command."""

from dtd.cli import main

main()
