"""Where a map's model comes from, so that worker processes can load it themselves."""

from __future__ import annotations

import functools
from dataclasses import dataclass

from closedloop.io.loader import load_model
from closedloop.model.closed_loop import ClosedLoopModel


@dataclass(frozen=True)
class ModelSource:
    """Where a model comes from, so that worker processes can load it themselves.

    Attributes: the arguments of :func:`closedloop.io.loader.load_model` (paths as strings;
    ``springs`` and ``args`` as sorted (name, value) pairs).
    """

    path: str
    closures: str | None = None
    springs: tuple = ()
    joint_stiffness: float | None = None
    args: tuple = ()

    def load(self) -> ClosedLoopModel:
        """The model (loaded once per process), without its visual geometry: nothing is
        drawn where a model is loaded so (the meshes of a UR5 take seconds to read)."""
        return _load(self)


@functools.lru_cache(maxsize=8)
def _load(source: ModelSource) -> ClosedLoopModel:
    springs = {k: list(v) if isinstance(v, tuple) else v for k, v in source.springs}
    return load_model(
        source.path,
        source.closures,
        springs=springs or None,
        joint_stiffness=source.joint_stiffness,
        args=dict(source.args) or None,
        geometry=False,
    )


def model_of(model: ClosedLoopModel | ModelSource) -> ClosedLoopModel:
    """``model`` itself, or the model a :class:`ModelSource` loads (once per process)."""
    return model.load() if isinstance(model, ModelSource) else model
