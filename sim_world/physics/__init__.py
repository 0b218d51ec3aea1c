"""Physics and autopilot: the quadrotor (rotors, motor lag, drag), the PX4-style cascade autopilot, wind."""
