"""``python -m gyroarray.cli``."""

from gyroarray.cli.main import main

raise SystemExit(main())
