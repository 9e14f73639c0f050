"""``python -m corraoi.cli``: the command line."""

from . import run

run()
