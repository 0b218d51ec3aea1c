"""Deciding: the action space, the planners (the paper's latent model in `latent/`), the centring loop.

Nothing here knows how a mission is set up or reported; `controller.missions` does that.
"""
