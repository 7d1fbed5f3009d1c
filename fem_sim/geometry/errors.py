"""The one error type of fem_sim.geometry (a user's mesh, surface or mask cannot be used)."""


class GeometryError(ValueError):
    """A mesh file cannot be used; the message names the file and what is wrong."""
