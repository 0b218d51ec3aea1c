"""Research: training the image detector (its data and training loop)."""
