"""``python -m mpf_mavlink.bench``: the benchmark figures as JSON (scripts/bench)."""

from mpf_mavlink.bench.main import main

raise SystemExit(main())
