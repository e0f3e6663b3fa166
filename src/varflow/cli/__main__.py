"""``python -m varflow.cli``: the ``varflow`` command line."""

from . import main

raise SystemExit(main())
