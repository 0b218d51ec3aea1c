"""Typed errors of the latent planner package; each message names the file or field at fault."""

from __future__ import annotations


class LatentError(Exception):
    """Base class of every error raised by `controller.planning.latent`."""


class PlannerCheckpointError(LatentError):
    """A checkpoint folder is missing a file, is corrupt, or does not match its config."""


class InstructionError(LatentError, ValueError):
    """An instruction cannot be used (empty, or an instruction file is malformed)."""


class ImageInputError(LatentError, ValueError):
    """An image handed to the planner has a shape or dtype that cannot be used."""


class TrainingDataError(LatentError):
    """A dataset folder is missing files or holds malformed rows."""
