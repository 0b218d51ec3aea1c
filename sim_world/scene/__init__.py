"""The inspection scene: configuration (domain randomisation ranges), sampling, assets and bodies, truth."""
