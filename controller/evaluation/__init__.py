"""Research: evaluating the latent planner.

Accuracy, presence, the paper's experiments, plots, the Gymnasium task.
"""
