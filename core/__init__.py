"""roadload: an open testbed for vehicle tractive-force estimation and eco-driving control.

``import roadload`` stays light (the ``roadload`` command imports it before it reads its arguments): ``Trip`` and
``TripError`` load with their module on first use (PEP 562), and the gym ids below are registered with string entry
points when gymnasium is imported (at once if it is loaded already).
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import importlib.util
import sys
from types import ModuleType
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
# Gymnasium 1.x scans no plugin entry points, so ``import roadload`` registers the ids, with string entry points (the
# env modules load only on ``gymnasium.make``). ``gymnasium.make("roadload:roadload/EcoDrive-v0")`` imports
# ``roadload`` first, which is what makes the ids resolve in SubprocVecEnv workers started with spawn or forkserver.
# EcoDrive-v0 and EcoTraffic-v0 also have a native vector env (``gymnasium.make_vec(...,
# vectorization_mode="vector_entry_point")``, roadload.gym.vector / .traffic). The envs truncate at their own
# configured time limit, hence no max_episode_steps.
# gymnasium itself (11 MB of a process's RSS) is not imported for that: with gymnasium loaded already the ids are
# registered at once, else as soon as gymnasium's import completes (:class:`_RegisterOnGymnasiumImport`), so the
# command line and a streamed simulation never load it.
GYM_ENVS = (("roadload/EcoDrive-v0", "roadload.gym.ecodrive:EcoDriveEnv", "roadload.gym.vector:make_vector_env"),
            ("roadload/EcoHighway-v0", "roadload.gym.highway:EcoHighwayEnv", None),
            ("roadload/EcoTraffic-v0", "roadload.gym.traffic:EcoTrafficEnv", "roadload.gym.traffic:make_vector_env"))


def _register_gym_envs() -> None:
    import gymnasium

    for env_id, entry_point, vector_entry_point in GYM_ENVS:
        if env_id not in gymnasium.registry:
            gymnasium.register(id=env_id, entry_point=entry_point, vector_entry_point=vector_entry_point,
                               disable_env_checker=False)


class _RegisterOnGymnasiumImport(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """An import hook on ``sys.meta_path`` (first): finds ``gymnasium`` with the other finders, runs its module as
    their loader does, then registers roadload's ids and leaves ``sys.meta_path``."""

    def find_spec(self, fullname: str, path: Any = None, target: Any = None) -> importlib.machinery.ModuleSpec | None:
        if fullname != "gymnasium":
            return None
        sys.meta_path.remove(self)
        spec = importlib.util.find_spec(fullname)
        if spec is None or spec.loader is None:
            return spec
        self._loader = spec.loader
        spec.loader = self
        return spec

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> ModuleType | None:
        return self._loader.create_module(spec)

    def exec_module(self, module: ModuleType) -> None:
        if module.__spec__ is not None:  # what gymnasium's own import would have set
            module.__spec__.loader = self._loader
        module.__loader__ = self._loader
        self._loader.exec_module(module)
        _register_gym_envs()


if "gymnasium" in sys.modules:
    _register_gym_envs()
elif not any(isinstance(finder, _RegisterOnGymnasiumImport) for finder in sys.meta_path):
    sys.meta_path.insert(0, _RegisterOnGymnasiumImport())
