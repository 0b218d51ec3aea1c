"""Research: benchmarks that print numbers (missions, faults, flight, PX4, perception, planner latency, the simulator)."""
