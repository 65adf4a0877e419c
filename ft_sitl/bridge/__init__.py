"""Autopilot in the loop: our physics, scenarios and sensors as the simulator of a real
PX4 (HIL over TCP 4560+i) or ArduPilot (SIM_JSON over UDP 9002). Reference:
docs/autopilot-in-the-loop.md."""

ARDUPILOT_DEFAULT_PORT = 9002  # SITL_cmdline.cpp: SIM_OUT_PORT (+ 10 per --instance)
"""The UDP port ArduPilot SITL sends its servo packets to (here, so the command line can
show it without loading the bridge)."""
