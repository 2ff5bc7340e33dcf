"""``python -m colossus``: the command line."""

from colossus.cli import main

if __name__ == "__main__":  # pragma: no branch
    main(prog_name="colossus")
