"""Start-up stays light: the package and the command line's ``--help`` and ``--version``
import none of the heavy packages, and the envs are still registered with Gymnasium
whichever is imported first.  Each check runs in a fresh interpreter, since this test
process has imported everything long before."""

from __future__ import annotations

import contextlib
import io
import json
import subprocess
import sys

import pytest

HEAVY = ("scipy", "gymnasium", "pybullet", "matplotlib", "torch")


def _imported_after(code: str) -> list[str]:
    """The heavy top-level packages a fresh interpreter holds after running ``code``."""
    probe = (f"import sys\n{code}\n"
             f"print(__import__('json').dumps(sorted(m for m in {HEAVY!r} "
             "if m in sys.modules)))")
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True,
                         check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


@pytest.mark.parametrize("argv", [["--version"], ["--help"]])
def test_the_command_lines_own_options_import_nothing_heavy(argv: list[str]) -> None:
    code = ("from calibrators.cli import main\n"
            "import contextlib, io\n"
            "with contextlib.redirect_stdout(io.StringIO()):\n"
            f"    try:\n        main({argv!r})\n    except SystemExit:\n        pass")
    assert _imported_after(code) == []


#: Commands whose ``--help`` needs nothing heavy: the others list the registered agents
#: and estimators, found by importing them.
LIGHT_HELP = ("pose", "render", "urdf", "session", "fit", "compensate", "verify", "design",
              "conditions")


@pytest.mark.parametrize("command", LIGHT_HELP)
def test_a_commands_help_imports_nothing_heavy(command: str) -> None:
    code = ("from calibrators.cli import main\n"
            "import contextlib, io\n"
            "with contextlib.redirect_stdout(io.StringIO()):\n"
            f"    try:\n        main([{command!r}, '--help'])\n    except SystemExit:\n"
            "        pass")
    assert _imported_after(code) == []


def test_a_command_imports_only_its_own_module() -> None:
    """Parsing ``conditions`` imports no other command's module."""
    code = ("from calibrators.cli import build_parser\n"
            "build_parser('conditions').parse_args(['conditions'])\n"
            "print(__import__('json').dumps(sorted(m for m in sys.modules\n"
            "                                        if m.startswith('calibrators.cli.'))))")
    probe = f"import sys\n{code}"
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True,
                         check=True).stdout
    loaded = set(json.loads(out.strip().splitlines()[-1]))
    assert "calibrators.cli.conditions" in loaded
    assert not loaded & {"calibrators.cli.compare", "calibrators.cli.calibrate",
                         "calibrators.cli.plan", "calibrators.cli.pose"}


def test_importing_the_package_imports_no_heavy_package() -> None:
    assert _imported_after("import orthoglide_env\nimport orthoglide_env.model.kinematics") == []


@pytest.mark.parametrize("order", ["package first", "gymnasium first"])
def test_the_envs_are_registered_in_either_import_order(order: str) -> None:
    imports = (["import orthoglide_env", "import gymnasium"] if order == "package first"
               else ["import gymnasium", "import orthoglide_env"])
    code = "\n".join([*imports,
                      "env = gymnasium.make(orthoglide_env.ENV_ID, backend='exact')",
                      "env.reset(seed=0)",
                      "assert orthoglide_env.LAB_ENV_ID in gymnasium.registry",
                      "assert orthoglide_env.FLAT_LAB_ENV_ID in gymnasium.registry"])
    assert "gymnasium" in _imported_after(code)


def test_an_env_id_with_its_module_registers_it() -> None:
    """Gymnasium's ``module:id`` form imports the package, which registers at once."""
    code = ("import gymnasium\n"
            "env = gymnasium.make('orthoglide_env:OrthoglideLab-v0')\n"
            "assert type(env.unwrapped).__name__ == 'OrthoglideLabEnv'")
    assert "gymnasium" in _imported_after(code)


def test_a_comparison_and_a_plan_import_no_scipy_stats() -> None:
    """A comparison (its command's module, the study, its statistics) needs SciPy's special
    functions only: ``scipy.stats`` alone costs it a tenth of a 1000-machine run.  Nor does
    ``plan`` import it (a CPU-second of each start), though it can plan a verification."""
    code = ("import calibrators.cli.compare, calibrators.study.compare, calibrators.cli.plan\n"
            "print(__import__('json').dumps(sorted(m for m in sys.modules\n"
            "                                        if m.startswith('scipy.stats'))))")
    out = subprocess.run([sys.executable, "-c", f"import sys\n{code}"], capture_output=True,
                         text=True, check=True).stdout
    assert json.loads(out.strip().splitlines()[-1]) == []


def test_a_sweeps_modules_import_no_scipy() -> None:
    """What a sweep of the planning agents imports in its processes (the study, the agents,
    the planner and the bound's modules) loads no SciPy: its special functions load where
    a fit is judged or a reach asked, its linear algebra where a bound is solved (never, in
    a sweep's processes), a third of each one's start-up.  The statistics that lived in the
    study are still found there."""
    code = ("import calibrators.compare, calibrators.agents.active, calibrators.agents.optimal\n"
            "import calibrators.planning.warm_bound, orthoglide_env.envs.lab_vector")
    assert _imported_after(code) == ["gymnasium"]
    from calibrators.study import compare, statistics

    assert compare.summary is statistics.summary
    assert compare.MIN_INTERVAL == statistics.MIN_INTERVAL
    with pytest.raises(AttributeError, match="no attribute 'nothing'"):
        compare.nothing  # noqa: B018


def test_a_comparison_imports_only_the_agents_it_plays() -> None:
    """``compare --agents paper`` imports the paper's agent alone: not the other agents'
    modules, the planner's (with SciPy's linear algebra), the learned policy's beliefs or,
    without a progress bar, tqdm: a tenth of a 1000-machine comparison's CPU.  Its
    ``--help`` still names every agent (:class:`calibrators.cli.parser.Listed`)."""
    code = ("from calibrators.cli import main\n"
            "import contextlib, io\n"
            "with contextlib.redirect_stdout(io.StringIO()):\n"
            "    main(['compare', '--agents', 'paper', '--estimators', 'paper6',\n"
            "          '--machines', '1', '--quiet'])\n"
            "print(__import__('json').dumps(sorted(m for m in sys.modules if m.startswith(\n"
            "    ('calibrators.agents.', 'calibrators.planning', 'scipy.linalg', 'tqdm')))))")
    out = subprocess.run([sys.executable, "-c", f"import sys\n{code}"], capture_output=True,
                         text=True, check=True).stdout
    assert json.loads(out.strip().splitlines()[-1]) == [
        "calibrators.agents.base", "calibrators.agents.names", "calibrators.agents.paper",
        "calibrators.agents.reference"]
    from calibrators.agents import available
    from calibrators.cli import main

    with pytest.raises(SystemExit), contextlib.redirect_stdout(io.StringIO()) as shown:
        main(["compare", "--help"])
    # (the help's lines wrap anywhere, at a name's hyphen too)
    assert "".join(", ".join(available()).split()) in "".join(shown.getvalue().split())
