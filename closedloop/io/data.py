"""Model files by name: the bundled test mechanisms and the example-robot-data robots.

Example::

    import closedloop as cl
    from closedloop import data

    robot = cl.load_model(data.path("fourbar.urdf"), data.path("fourbar.yaml"))
    ur5 = cl.load_model(data.robot_file("ur5"))   # example-robot-data's UR5 URDF

The bundled files are the repository's ``urdf/`` folder; an installed wheel carries them as
``closedloop/_data/urdf`` (``pyproject.toml``), a source tree or editable install reads
``urdf/`` beside the package. :func:`resolve` turns a command-line MODEL (a file, a bundled
model name or a robot name) into the robot file and its closure file.
"""

from __future__ import annotations

import sys
from pathlib import Path

from closedloop.exceptions import ModelFileError, did_you_mean

#: Bundled models by name: robot file and closure file (None: none) in :func:`data_dir`.
#: ``NAME`` is the URDF ``NAME.urdf`` with its closure file ``NAME.yaml``, ``NAME_mjcf``
#: the same machine written for MuJoCo, ``NAME.xml`` (loops and actuators in the file).
BUNDLED_MODELS: dict[str, tuple[str, str | None]] = {
    **{
        name: (f"{name}.urdf", f"{name}.yaml")
        for name in ("fourbar", "fivebar5", "rrr3", "delta", "stewart", "cahyman")
    },
    **{
        f"{name}_mjcf": (f"{name}.xml", None)
        for name in ("fourbar", "fivebar5", "rrr3", "delta", "stewart")
    },
}
#: example-robot-data robots by name: URDF under :func:`robot_data_dir`.
ROBOTS: dict[str, str] = {
    "ur3": "ur_description/urdf/ur3_robot.urdf",
    "ur5": "ur_description/urdf/ur5_robot.urdf",
    "ur10": "ur_description/urdf/ur10_robot.urdf",
    "panda": "panda_description/urdf/panda.urdf",
    "kinova": "kinova_description/robots/kinova.urdf",
    "xarm7": "xarm_description/urdf/xarm7.urdf",
    "z1": "z1_description/urdf/z1.urdf",
}

_PACKAGE = Path(__file__).resolve().parents[1]


def data_dir() -> Path:
    """Folder of the bundled model files: ``closedloop/_data/urdf`` in an installed wheel,
    else the source tree's ``urdf/``.

    Raises:
        ModelFileError: neither folder exists (a broken installation).
    """
    for folder in (_PACKAGE / "_data" / "urdf", _PACKAGE.parent / "urdf"):
        if folder.is_dir():
            return folder
    raise ModelFileError(
        f"no bundled model folder: neither {str(_PACKAGE / '_data' / 'urdf')!r} nor "
        f"{str(_PACKAGE.parent / 'urdf')!r} exists"
    )


def path(name: str) -> Path:
    """Path of the bundled file ``name`` (e.g. ``"fourbar.urdf"``), from any folder.

    Raises:
        ModelFileError: ``name`` is not a bundled file (the message lists them).
    """
    if not isinstance(name, str):
        raise ModelFileError(f"bundled file name must be a str, got {type(name).__name__}")
    folder = data_dir()
    file = folder / name
    if not file.is_file():
        names = sorted(p.name for p in folder.iterdir() if p.is_file())
        raise ModelFileError(
            f"no bundled file {name!r}{did_you_mean(name, names)}; expected one of {names}"
        )
    return file


def robot_file(name: str) -> Path:
    """URDF of the example-robot-data robot ``name`` (one of :data:`ROBOTS`).

    Raises:
        ModelFileError: unknown name (the message lists them), example-robot-data missing.
    """
    if name not in ROBOTS:
        raise ModelFileError(
            f"unknown robot {name!r}{did_you_mean(name, ROBOTS)}; expected one of {sorted(ROBOTS)}"
        )
    return robot_data_dir() / ROBOTS[name]


def resolve(model: str | Path, closures: str | Path | None = None) -> tuple[Path, Path | None]:
    """(robot file, closure file) of a command-line MODEL.

    An existing file is itself; otherwise a bundled model name (:data:`BUNDLED_MODELS`,
    which brings its closure file unless ``closures`` is given) or a robot name
    (:data:`ROBOTS`). Anything else with a suffix is returned as given, for the loader
    to report.

    Raises:
        ModelFileError: MODEL is no file, no name, and has no suffix (a mistyped name).
    """
    text = str(model)
    if Path(text).exists() or (text not in BUNDLED_MODELS and text not in ROBOTS):
        if not Path(text).exists() and not Path(text).suffix:
            raise ModelFileError(
                f"model {text!r} is neither a file nor a known name"
                f"{did_you_mean(text, [*BUNDLED_MODELS, *ROBOTS])}; expected a robot file "
                f"or one of {sorted(BUNDLED_MODELS)} (bundled), {sorted(ROBOTS)} "
                "(example-robot-data)"
            )
        return Path(text), None if closures is None else Path(closures)
    if text in ROBOTS:
        return robot_file(text), None if closures is None else Path(closures)
    robot, side = BUNDLED_MODELS[text]
    if closures is not None:
        return path(robot), Path(closures)
    return path(robot), None if side is None else path(side)


#: Where a cmeel wheel puts example-robot-data's robot files, under a site-packages folder.
CMEEL_ROBOTS = ("cmeel.prefix", "share", "example-robot-data", "robots")


def robot_data_dir() -> Path:
    """Folder ``robots/`` of the installed example-robot-data distribution.

    The package ships no Python module, only files under its cmeel prefix: the folder
    :data:`CMEEL_ROBOTS` of a folder on ``sys.path`` when there is one (the wheel's
    layout), else the one the distribution's file list names.
    """
    for folder in sys.path:
        robots = Path(folder or ".", *CMEEL_ROBOTS)
        if robots.is_dir():
            return robots
    import importlib.metadata  # on demand: 20-30 ms of a command line's start-up

    try:
        dist = importlib.metadata.distribution("example-robot-data")
    except importlib.metadata.PackageNotFoundError:
        raise ModelFileError("example-robot-data is not installed") from None
    for f in dist.files or ():
        parts = Path(f).parts
        if "example-robot-data" in parts and "robots" in parts:
            i = parts.index("robots")
            return Path(dist.locate_file(Path(*parts[: i + 1])))
    raise ModelFileError("example-robot-data is installed but its robots folder was not found")
