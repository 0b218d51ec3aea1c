"""sim_world package."""
