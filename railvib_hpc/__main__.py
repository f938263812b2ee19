"""``python -m railvib_hpc``: the command line (:mod:`railvib_hpc.cli`)."""

from .cli import main

raise SystemExit(main())
