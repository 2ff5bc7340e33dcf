"""The runtime's exceptions."""


class ColliderError(Exception):
    """A collider asset cannot be read or fails verification (one-line message)."""
