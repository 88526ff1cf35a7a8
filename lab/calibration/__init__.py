"""Identification of the SIL autopilot emulation from the real firmware, and the calibration
check that compares SIL and firmware flights mission by mission."""
