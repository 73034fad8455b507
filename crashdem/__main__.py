"""``python -m crashdem ...``: the ``crashdem`` command (``crashdem.cli.main``)."""
from crashdem.cli import main

raise SystemExit(main())
