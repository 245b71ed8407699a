"""``python -m gyroarray.cli``."""

from gyroarray.cli.main import main

if __name__ == "__main__":          # imported (the API docs' autosummary), it runs nothing
    raise SystemExit(main())
