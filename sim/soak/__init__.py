"""The reliability and security campaign (``scripts/soak``): the SIL vehicle and the real bridge
over loopback UDP through an impairment relay (:mod:`sim.soak.relay`), a MAVLink frame fuzzer
(:mod:`sim.soak.mavfuzz`), the scenarios (missions, bad input) and their checks."""
