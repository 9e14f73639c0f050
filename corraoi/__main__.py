"""``python -m corraoi``: the command line."""

from .cli import main

main(prog_name="corraoi")
