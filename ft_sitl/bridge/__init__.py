"""Autopilot in the loop: our physics, scenarios and sensors as the simulator of a real
PX4 (HIL over TCP 4560+i) or ArduPilot (SIM_JSON over UDP 9002). Reference:
docs/autopilot-in-the-loop.md."""
