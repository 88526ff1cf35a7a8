"""``python -m sim.soak`` (``scripts/soak``): the reliability and security campaign."""

from sim.soak.campaign import main

raise SystemExit(main())
