"""drivefuzz: a SUMO-backed fuzzer for automated-driving controllers.

Importing the package makes sure ``SUMO_HOME`` points at the installed ``sumo``
package (a virtual environment does not set it, and SUMO needs it for its XML
schemas and tools).
"""

from __future__ import annotations

import os

__version__ = "0.1.0"


def _ensure_sumo_home() -> None:
    if os.environ.get("SUMO_HOME"):
        return
    try:
        import sumo  # the eclipse-sumo wheel
    except ImportError:  # pragma: no cover - eclipse-sumo is a dependency
        return
    os.environ["SUMO_HOME"] = os.path.dirname(sumo.__file__)


_ensure_sumo_home()


def sumo_binary(name: str = "sumo") -> str:
    """Path of a SUMO executable (``sumo``, ``sumo-gui``, ``netconvert``...) from the installed package."""
    path = os.path.join(os.environ["SUMO_HOME"], "bin", name)
    return path if os.path.exists(path) else name
