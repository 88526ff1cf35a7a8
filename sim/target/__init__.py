"""The simulated target's MAVLink feed as a real tracker reports it (rate, noise, latency,
drop-outs: :mod:`sim.target.feed`) and its plot."""
