"""``python -m lab.rigs px4|arduplane --out DIR`` (``scripts/sitl``)."""

from lab.rigs.common import main

raise SystemExit(main())
