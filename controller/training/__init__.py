"""Research: training the latent planner (data, augmentation, losses, the training loop)."""
