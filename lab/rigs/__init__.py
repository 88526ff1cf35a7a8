"""Real-firmware rigs: PX4 SITL (SIH) and ArduPlane SITL flown by ``mpf-mavlink run``.

``common`` is the rig (arguments, mission placement, hand-over, figures, table); ``px4`` and
``arduplane`` start and take off their firmware; ``bundles`` finds and unpacks the SITL bundles.
"""
