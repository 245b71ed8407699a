"""The command line: ``gyroarray`` (:func:`gyroarray.cli.main.main`)."""
