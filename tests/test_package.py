"""The packages' names, imported on first use: every public name resolves, and importing a
small module does not load the heavy ones."""

import subprocess
import sys
import types

import pytest

import cahyman_pin
import closedloop


def modules_after(statement: str) -> set[str]:
    """The modules loaded by ``statement`` in a fresh interpreter."""
    code = f"import sys; {statement}; print(' '.join(sorted(sys.modules)))"
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=120, check=True)  # fmt: skip
    return set(done.stdout.split())


def loaded_after(statement: str) -> set[str]:
    """The top-level modules loaded by ``statement`` in a fresh interpreter."""
    return {name.split(".")[0] for name in modules_after(statement)}


@pytest.mark.parametrize("package", [closedloop, cahyman_pin])
def test_every_public_name_resolves(package):
    for name in package.__all__:
        value = getattr(package, name)
        assert value is not None
        assert name in dir(package)
    with pytest.raises(AttributeError, match="no attribute 'nothing'"):
        package.nothing  # noqa: B018


def test_compliance_is_the_function_even_after_its_module_is_imported():
    import closedloop.elastostatics.compliance  # binds the submodule's name in the package
    from closedloop.elastostatics.compliance import compliance

    assert closedloop.compliance is compliance
    assert isinstance(compliance, types.FunctionType)
    assert isinstance(closedloop.data, types.ModuleType)  # a submodule that is a name


@pytest.mark.parametrize(
    ("statement", "absent"),
    [
        ("import closedloop", {"pinocchio", "scipy", "yaml", "matplotlib", "meshcat"}),
        ("import closedloop.exceptions", {"pinocchio", "scipy", "numpy"}),
        ("import cahyman_pin", {"pinocchio", "scipy", "yaml", "matplotlib"}),
        ("import cahyman_pin.params", {"pinocchio", "scipy", "matplotlib"}),
        ("from closedloop import InvalidInputError", {"pinocchio", "scipy"}),
    ],
)
def test_importing_a_light_module_loads_no_heavy_one(statement, absent):
    assert not loaded_after(statement) & absent


def test_the_stiffness_command_loads_no_plotting_viewer_yaml_or_scipy_linalg():
    modules = modules_after(
        "import os; from cahyman_pin.cli import main; sys.stdout = open(os.devnull, 'w'); "
        "assert main(['stiffness', '--json']) == 0; sys.stdout = sys.__stdout__"
    )
    loaded = {name.split(".")[0] for name in modules}
    assert "pinocchio" in loaded  # the generic backend ran
    assert "scipy.linalg._flapack" in modules  # its LAPACK, without the package's code
    assert not loaded & {"matplotlib", "meshcat", "tqdm", "markdown", "dask", "yaml"}
    assert not modules & {"scipy.linalg", "importlib.metadata", "numpy.f2py"}


def test_the_closedloop_stiffness_command_loads_no_map_machinery():
    modules = modules_after(
        "import os; from closedloop.cli.app import main; sys.stdout = open(os.devnull, 'w'); "
        "assert main(['stiffness', 'fourbar', '--frame', 'P', '--actuated', '0.3']) == 1; "
        "sys.stdout = sys.__stdout__"
    )
    assert (
        "closedloop.elastostatics.compliance" in modules
    )  # the query ran (exit 1: a planar mechanism)
    assert not modules & {
        "closedloop.analysis.map_engine",
        "closedloop.cli.map",
        "tqdm",
        "scipy.linalg",
    }


#: What a query of a serial URDF robot does not use: the other formats' readers, beam
#: theory, balls and elastic closures, gravity and the assembly (a --q is given), the
#: distributions' metadata (the robot files are found on sys.path), temporary files.
NOT_FOR_A_URDF_QUERY = {
    "closedloop.io.mjcf",
    "closedloop.io.mjcf_xml",
    "closedloop.io.sdf",
    "closedloop.io.sdf_reader",
    "closedloop.model.beam_section",
    "closedloop.model.beam_theory",
    "closedloop.model.beams",
    "closedloop.model.balls",
    "closedloop.model.elastic_closures",
    "closedloop.model.gravity",
    "closedloop.kinematics.assembly",
    "closedloop.elastostatics.preload",
    "closedloop.elastostatics.statics",
    "closedloop.viewer",
    "closedloop.cli.view",
    "importlib.metadata",
    "tempfile",
    "numpy.ma",
    "difflib",
}
UR5_STIFFNESS = ["stiffness", "ur5", "--frame", "tool0", "--q", "0", "-1.0", "1.5", "-0.5",
                 "1.2", "0.3", "--joint-stiffness", "1e4"]  # fmt: skip


def _command_modules(module: str, argv: list[str], status: int) -> set[str]:
    return modules_after(
        f"import os; from {module} import main; sys.stdout = open(os.devnull, 'w'); "
        f"assert main({argv!r}) == {status}; sys.stdout = sys.__stdout__"
    )


def test_a_urdf_stiffness_query_imports_only_what_it_uses():
    modules = _command_modules("closedloop.cli.app", UR5_STIFFNESS, 0)
    assert "closedloop.elastostatics.query" in modules  # the query ran
    assert not modules & NOT_FOR_A_URDF_QUERY, sorted(modules & NOT_FOR_A_URDF_QUERY)
    loaded = {name.split(".")[0] for name in modules}
    assert not loaded & {"matplotlib", "meshcat", "yaml", "dask", "tqdm"}


def test_closedloop_info_imports_no_compliance():
    modules = _command_modules("closedloop.cli.app", ["info", "ur5"], 0)
    assert "closedloop.cli.info" in modules
    assert not modules & {"closedloop.elastostatics", "closedloop.cli.stiffness"}
    assert not modules & NOT_FOR_A_URDF_QUERY, sorted(modules & NOT_FOR_A_URDF_QUERY)


def test_the_cahyman_stiffness_command_reads_no_model_file():
    """CaHyMan's model is built in memory: no reader of robot files, no beam theory
    without its links as beams."""
    modules = _command_modules("cahyman_pin.cli", ["stiffness", "--json"], 0)
    assert "closedloop.elastostatics.query" in modules
    absent = NOT_FOR_A_URDF_QUERY - {"closedloop.kinematics.assembly"}
    absent |= {"closedloop.io.loader", "closedloop.io.robot_files"}
    assert not modules & absent, sorted(modules & absent)


def test_the_api_layout_page_lists_every_module_of_every_layer():
    from helpers import REPO

    page = (REPO / "docs/api/layout.md").read_text()
    for init in sorted((REPO / "closedloop").glob("*/__init__.py")):
        layer = init.parent.name
        section = page.split(f".. automodule:: closedloop.{layer}\n", 1)
        assert len(section) == 2, f"docs/api/layout.md has no section for closedloop.{layer}"
        listed = section[1].split("```", 1)[0].split()
        modules = sorted(p.stem for p in init.parent.glob("*.py") if p.stem != "__init__")
        assert [m for m in listed if m in modules] == modules, f"closedloop.{layer}"
