"""Registry of the sub-commands beyond ``analyze`` (each module exposes ``register(subparsers)``)."""

from __future__ import annotations

from .cli_synthesis import register as _synthesis

REGISTER: list = [_synthesis]

# issue 4: Monte Carlo, worst pose, workspace map
from .montecarlo import register as _montecarlo  # noqa: E402
from .workspace import register as _workspace  # noqa: E402

REGISTER += [_montecarlo, _workspace]
