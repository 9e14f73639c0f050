"""``python -m corraoi``: the command line."""

from .cli import run

run()
