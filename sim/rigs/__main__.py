"""``python -m sim.rigs px4|arduplane --out DIR`` (``scripts/sitl``)."""

from sim.rigs.common import main

raise SystemExit(main())
