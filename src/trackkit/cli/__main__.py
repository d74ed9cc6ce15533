"""``python -m trackkit.cli``: the ``trackkit`` command."""

from trackkit.cli import main

if __name__ == "__main__":
    main()
