"""``python -m mpf_mavlink.cli``: the same as the ``mpf-mavlink`` command."""

from mpf_mavlink.cli.main import main

raise SystemExit(main())
