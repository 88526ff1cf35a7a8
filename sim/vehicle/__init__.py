"""The SIL vehicle: a plant, the autopilot emulation, a MAVLink endpoint (link, telemetry
streams, the target's system, ground-station services) and clocks, composed by
:class:`sim.vehicle.vehicle.SimVehicle` and configured by one
:class:`sim.vehicle.config.VehicleConfig`."""
