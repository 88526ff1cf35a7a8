"""The laboratory beside the product (not shipped: pyproject's packages are ``mpf_mavlink`` and
``sim``): the rigs that fly the real PX4 / ArduPlane SITL bundles against the bridge
(``rigs``, scripts/sitl), the soak (``soak``, scripts/soak) and the identification of the
autopilot profiles from firmware flights (``calibration``). It may import everything that
ships; nothing that ships imports it."""
