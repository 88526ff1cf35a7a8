"""``python -m sim.vehicle``: one SIL vehicle on a MAVLink link (see :func:`main`)."""

from sim.vehicle.vehicle import main

raise SystemExit(main())
