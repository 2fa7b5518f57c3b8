"""Registry of the sub-commands beyond ``analyze`` (each module exposes ``register(subparsers)``)."""

from __future__ import annotations

from .cli_synthesis import register as _synthesis

REGISTER: list = [_synthesis]
