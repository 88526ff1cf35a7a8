"""``python -m lab.soak`` (``scripts/soak``): the reliability and security campaign."""

from lab.soak.campaign import main

raise SystemExit(main())
