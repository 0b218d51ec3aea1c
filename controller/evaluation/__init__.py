"""Research: evaluating the latent planner (accuracy, presence, the paper's experiments, plots, the Gymnasium task)."""
