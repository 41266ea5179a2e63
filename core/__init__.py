"""roadload: an open testbed for vehicle tractive-force estimation and eco-driving control.

``import roadload`` stays light (the ``roadload`` command imports it before it reads its arguments): ``Trip`` and
``TripError`` load with their module on first use (PEP 562), and the gym ids below are registered with string entry
points.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from .trip import Trip, TripError

__version__ = "0.1.0"
__all__ = ["Trip", "TripError", "__version__"]
_LAZY = {"Trip": ".trip", "TripError": ".trip_schema"}


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name], __name__), name)
    raise AttributeError(f"module 'roadload' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))


# --- gymnasium registration -------------------------------------------------------------------------------------
# Gymnasium 1.x scans no plugin entry points, so the ids are registered when ``roadload`` is imported, with string
# entry points (the env modules load only on ``gymnasium.make``). ``gymnasium.make("roadload:roadload/EcoDrive-v0")``
# imports ``roadload`` first, which is what makes the ids resolve in SubprocVecEnv workers started with spawn or
# forkserver. EcoDrive-v0 and EcoTraffic-v0 also have a native vector env
# (``gymnasium.make_vec(..., vectorization_mode="vector_entry_point")``, roadload.gym.vector / .traffic). The envs
# truncate at their own configured time limit, hence no max_episode_steps.
def _register_gym_envs() -> None:
    import gymnasium

    for env_id, entry_point, vector_entry_point in (
            ("roadload/EcoDrive-v0", "roadload.gym.ecodrive:EcoDriveEnv", "roadload.gym.vector:make_vector_env"),
            ("roadload/EcoHighway-v0", "roadload.gym.highway:EcoHighwayEnv", None),
            ("roadload/EcoTraffic-v0", "roadload.gym.traffic:EcoTrafficEnv", "roadload.gym.traffic:make_vector_env")):
        if env_id not in gymnasium.registry:
            gymnasium.register(id=env_id, entry_point=entry_point, vector_entry_point=vector_entry_point,
                               disable_env_checker=False)


_register_gym_envs()
