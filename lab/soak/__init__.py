"""The reliability and security campaign (``scripts/soak``): the SIL vehicle and the real bridge
over loopback UDP through an impairment relay (:mod:`lab.soak.relay`), a MAVLink frame fuzzer
(:mod:`lab.soak.mavfuzz`), the scenarios (missions, bad input) and their checks."""

import os

# MAVLink 2 framing in pymavlink and a quiet JSBSim: set here, before any module of the package
# imports either (the package is imported before its modules)
os.environ.setdefault("MAVLINK20", "1")
os.environ.setdefault("JSBSIM_DEBUG", "0")
