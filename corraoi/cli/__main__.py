"""``python -m corraoi.cli``: the command line."""

from . import main

main(prog_name="corraoi")
