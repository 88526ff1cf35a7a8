"""``python -m bench``: the benchmark figures as JSON (scripts/bench)."""

from bench.main import main

raise SystemExit(main())
