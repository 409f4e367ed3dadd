"""The node's start-up error (its own module: the node and its PX4 input both raise it)."""

from __future__ import annotations


class StartError(RuntimeError):
    """The node cannot start as configured (one line; ``main`` exits with code 2)."""
