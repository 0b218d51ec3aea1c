"""Research: benchmarks that print numbers.

Missions, faults, flight, PX4, perception, planner latency, the simulator.
"""
