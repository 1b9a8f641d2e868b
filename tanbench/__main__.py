"""`python -m tanbench`: the same entry point as the `tanbench` console script."""

from tanbench.cli import main

if __name__ == "__main__":
    main()
