"""``python -m pmdcid``: the command line, as the ``pmdcid`` script."""

from pmdcid.cli import main

if __name__ == "__main__":
    main(prog_name="pmdcid")
