"""Registry of the sub-commands beyond ``analyze`` (each module exposes ``register(subparsers)``)."""

from __future__ import annotations

REGISTER: list = []
