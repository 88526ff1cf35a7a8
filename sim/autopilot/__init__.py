"""The stock autopilot's rules as the SIL vehicle emulates them (PX4 commander, ArduPlane):
modes and their entry, offboard / GUIDED setpoints and their failsafes, commands and ACKs, and
what each mode flies through the inner loops (:mod:`sim.autopilot.inner_loop`)."""
