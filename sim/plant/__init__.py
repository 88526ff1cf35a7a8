"""The simulated airframes: the JSBSim aircraft (:mod:`sim.plant.jsbsim_plant`), the cheap
kinematic plant behind the same interface (:mod:`sim.plant.kinematic_plant`), the paper's
kinematic closed loop (:mod:`sim.plant.kinematic`), JSBSim trims and airframe identification."""
