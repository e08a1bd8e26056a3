"""truestep as a dependency: one import name, a public API, and what installed packages add.

Entry points are exercised with a fake installed distribution (a ``*.dist-info`` folder
with ``entry_points.txt`` on ``PYTHONPATH``), in a child interpreter so the registry
caches of this process stay as they are.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import textwrap
import zipfile
from importlib import metadata
from pathlib import Path

import pandas as pd
import pytest

import truestep

ROOT = Path(__file__).resolve().parents[2]


def _python(code: str, *, path: Path | None = None, cwd: Path | None = None) -> subprocess.CompletedProcess:
    env = dict(os.environ)
    if path is not None:
        env["PYTHONPATH"] = f"{path}{os.pathsep}{env.get('PYTHONPATH', '')}"
    return subprocess.run(
        [sys.executable, "-c", textwrap.dedent(code)],
        env=env,
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=300,
    )


def _cli(*args: str, path: Path | None = None) -> subprocess.CompletedProcess:
    return _python(f"import sys; from truestep.cli import main; sys.exit(main({list(args)!r}))", path=path)


def test_public_api_names_import_and_version_matches_the_metadata():
    for name in truestep.__all__:
        assert getattr(truestep, name) is not None, name
    assert truestep.__version__ == metadata.version("truestep")
    done = subprocess.run(
        [sys.executable, "-m", "truestep", "--version"], capture_output=True, text=True, check=True
    )
    assert done.stdout.strip() == f"truestep {truestep.__version__}"
    assert (
        "run"
        in subprocess.run(
            [sys.executable, "-m", "truestep", "--help"], capture_output=True, text=True, check=True
        ).stdout
    )


def test_the_built_engines_are_registered_by_entry_point_as_the_fallback_says():
    from truestep.adapters import BUILTIN, registered

    eps = {ep.name: ep.value for ep in metadata.entry_points(group="truestep.adapters")}
    assert {k: eps[k] for k in BUILTIN} == BUILTIN
    assert list(registered())[: len(BUILTIN)] == list(BUILTIN)


def test_the_wheel_holds_one_top_level_package_and_sits_beside_a_users_adapters(tmp_path):
    """`pip install .` (not editable) adds only `truestep`; a user's own `adapters/`
    package imports beside it."""
    wheels, source = tmp_path / "wheels", tmp_path / "source"
    # Built from a copy of the package's folders: setuptools writes build/ beside the source.
    source.mkdir()
    for part in ("pyproject.toml", "README.md", "truestep", "adapters", "cases", "reference_impl"):
        (shutil.copytree if (ROOT / part).is_dir() else shutil.copy)(
            ROOT / part,
            source / part,
            **({"ignore": shutil.ignore_patterns("__pycache__")} if (ROOT / part).is_dir() else {}),
        )
    subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "wheel",
            "--no-deps",
            "--no-build-isolation",
            "-q",
            "-w",
            str(wheels),
            str(source),
        ],
        check=True,
        capture_output=True,
        timeout=300,
    )
    (wheel,) = wheels.glob("truestep-*.whl")
    names = zipfile.ZipFile(wheel).namelist()
    tops = {n.split("/")[0] for n in names}
    assert tops == {"truestep", f"truestep-{truestep.__version__}.dist-info"}, tops
    assert "truestep/cases/harmonic-oscillator.toml" in names
    # every module of the checkout, at the path it is imported from (a subpackage missing
    # from pyproject's list installs a truestep whose every command fails at import)
    linked = ("adapters", "cases", "reference_impl")
    modules = {
        f"truestep/{path.relative_to(ROOT).as_posix()}"
        for part in linked
        for path in (ROOT / part).rglob("*.py")
        if "__pycache__" not in path.parts
    } | {
        path.relative_to(ROOT).as_posix()
        for path in (ROOT / "truestep").rglob("*.py")
        if "__pycache__" not in path.parts and path.relative_to(ROOT / "truestep").parts[0] not in linked
    }
    assert modules - set(names) == set()
    site = tmp_path / "site"
    subprocess.run(
        [sys.executable, "-m", "pip", "install", "--no-deps", "-q", "--target", str(site), str(wheel)],
        check=True,
        capture_output=True,
        timeout=300,
    )
    user = tmp_path / "user"
    (user / "adapters").mkdir(parents=True)
    (user / "adapters" / "__init__.py").write_text("MINE = 'the user project'\n")
    done = _python(
        f"""
        import adapters, truestep, truestep.adapters
        from truestep.adapters import get_adapter
        assert adapters.MINE == 'the user project'
        assert truestep.__file__.startswith({str(site)!r}), truestep.__file__
        assert get_adapter('reference').name == 'reference'
        from truestep.cli import main
        assert main(["list", "--cases", "free-fall", "--engines", "reference"]) == 0
        print('ok')
    """,
        path=Path(f"{user}{os.pathsep}{site}"),
        cwd=user,
    )
    assert done.stdout.strip().endswith("ok"), done.stderr


FAKE_ADAPTER = '''
import numpy as np
import truestep


class Drift(truestep.FixedStepAdapter):
    """Moves every particle at its start velocity: exact without forces."""
    name = "drift"
    methods = ("straight",)
    capabilities = frozenset({"point-masses", "2d", "3d"})

    def build(self, case, method, h):
        return [case.model.x0.copy(), case.model.v0.copy()]

    def advance(self, s, k, steps, h):
        s[0] = s[0] + steps * h * s[1]

    def read(self, s):
        return s[0], s[1]


def straight_line(case, t):
    m = case.model
    x = m.x0 + m.v0 * t[:, None, None]
    return truestep.Exact(t, x, np.broadcast_to(m.v0, x.shape).copy(), None)


class Decay(truestep.System):
    """y' = -rate y."""
    def __init__(self, y0, t0=0.0, *, rate=1.0):
        super().__init__(y0, t0)
        self.rate = rate

    def derivative(self, x, t):
        return -self.rate * x


def exact_decay(case, t):
    y = case.ode.y0 * np.exp(-case.ode.params["rate"] * t)[:, None]
    return truestep.Exact(t, y[:, None, :])
'''
GHOST_ADAPTER = "import an_engine_nobody_installed  # noqa\n"
DRIFT_CASE = """
kind = "particles"
[scene]
dimension = 2
[[scene.particles]]
position = [[0.0, 0.0, 0.0], [1.0, 1.0, 0.0]]
velocity = [[1.0, 0.5, 0.0], [-0.5, 0.0, 0.0]]
mass = 1.0
[run]
duration = 1.0
dt = [0.1, 0.05]
[reference]
exact = "straight-line"
[[gates]]
kind = "error"
engine = "*"
method = "*"
dt = 0.05
max = 1e-12
"""
DECAY_CASE = """
kind = "ode"
[ode]
system = "decay"
y0 = [1.0, 2.0, 3.0]
rate = 0.5
[run]
duration = 2.0
dt = [0.1, 0.05, 0.025]
quick_dt = [0.1, 0.05]
[reference]
exact = "exact-decay"
[[gates]]
kind = "order"
method = "rk4"
expect = 4.0
tol = 0.2
"""


@pytest.fixture(scope="module")
def fake_site(tmp_path_factory) -> Path:
    """A fake installed package registering an engine, a missing engine, a case directory,
    an exact solution and an ODE system."""
    site = tmp_path_factory.mktemp("site")
    (site / "fakepkg.py").write_text(FAKE_ADAPTER)
    (site / "ghost_adapter.py").write_text(GHOST_ADAPTER)
    cases = site / "fakecases"
    cases.mkdir()
    (cases / "__init__.py").write_text("")
    (cases / "drifting-pair.toml").write_text(DRIFT_CASE)
    (cases / "decay.toml").write_text(DECAY_CASE)
    info = site / "fakepkg-1.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: fakepkg\nVersion: 1.0\n")
    (info / "entry_points.txt").write_text(
        textwrap.dedent("""
        [truestep.adapters]
        drift = fakepkg:Drift
        ghost = ghost_adapter:Ghost
        [truestep.cases]
        fake = fakecases
        [truestep.exact]
        straight-line = fakepkg:straight_line
        exact-decay = fakepkg:exact_decay
        [truestep.systems]
        decay = fakepkg:Decay
    """)
    )
    return site


def test_installed_engines_and_cases_are_listed_and_a_missing_one_says_how_to_add_it(fake_site):
    done = _cli("list", path=fake_site)
    assert done.returncode == 0, done.stderr
    assert "drift      methods: straight" in done.stdout
    assert "drifting-pair" in done.stdout and "decay " in done.stdout
    assert "ghost      not installed (an_engine_nobody_installed is missing)" not in done.stdout
    assert "ghost      not installed: pip install the package that provides engine 'ghost'" in done.stdout
    built_in = _python("""
        import sys
        sys.modules['pymunk'] = None  # as if pymunk were not installed
        from truestep.cli import main
        sys.exit(main(['list', '--cases', 'free-fall', '--engines', 'pymunk']))
    """)
    assert 'pymunk     not installed: pip install "truestep[pymunk]"' in built_in.stdout
    named = _python("""
        import sys
        sys.modules['pymunk'] = None
        from truestep.cli import main
        sys.exit(main(['run', '--quick', '--cases', 'free-fall', '--engines', 'pymunk']))
    """)
    assert named.returncode == 2 and 'pip install "truestep[pymunk]"' in named.stderr
    assert "Traceback" not in named.stderr


def test_installed_engine_case_exact_and_system_run_and_gate(fake_site, tmp_path):
    out = tmp_path / "out"
    done = _cli(
        "run",
        "--quick",
        "--cases",
        "drifting-pair,decay",
        "--engines",
        "drift,reference",
        "--out",
        str(out),
        path=fake_site,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    assert "engine ghost left out" not in done.stderr  # named engines only
    gate = _cli("gate", "--results", str(out / "results.csv"), "-v", path=fake_site)
    assert gate.returncode == 0, gate.stdout + gate.stderr
    assert "ok   drifting-pair/error/drift/straight@0.05 (gates[0]" in gate.stdout
    assert "ok   decay/order/reference/rk4 (gates[0]" in gate.stdout
    # every installed engine by default, the missing one named; on the ODE case, which
    # the particle engines do not model (their rows are unsupported, not run)
    default = _cli("run", "--quick", "--cases", "decay", "--out", str(tmp_path / "all"), path=fake_site)
    assert default.returncode == 0, default.stderr[-3000:]
    assert "engine ghost left out: not installed" in default.stderr
    engines = set(pd.read_csv(tmp_path / "all" / "results.csv")["engine"])
    assert {"drift", "reference", "pymunk"} <= engines and "ghost" not in engines


def test_an_adapter_by_module_and_class_runs_unregistered(fake_site, tmp_path):
    out = tmp_path / "out"
    case = fake_site / "fakecases" / "drifting-pair.toml"
    done = _python(
        f"""
        import sys
        from importlib import metadata
        from truestep.cli import main
        assert 'drift' not in [e.name for e in metadata.entry_points(group='truestep.adapters')
                               if e.value == 'nothing']
        sys.exit(main(['run', '--quick', '--cases', {str(case)!r}, '--engines',
                       'fakepkg:Drift', '--out', {str(out)!r}]))
    """,
        path=fake_site,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    assert "drifting-pair,drift,straight" in (out / "results.csv").read_text()


def test_a_patched_class_replaces_the_registered_engine_of_its_name_saying_so(fake_site, tmp_path):
    """``--engines module:Class`` of a class named like a registered engine (a patched copy
    under test) runs in its place, and the run says which registration it replaced."""
    (fake_site / "patched.py").write_text(
        "import fakepkg\n\n\nclass Drift(fakepkg.Drift):\n"
        "    def advance(self, s, k, steps, h):\n"
        "        s[0] = s[0] + steps * h * 1.5 * s[1]  # a broken drift: half again too far\n"
    )
    out = tmp_path / "out"
    case = fake_site / "fakecases" / "drifting-pair.toml"
    done = _cli(
        "run",
        "--quick",
        "--cases",
        str(case),
        "--engines",
        "patched:Drift",
        "--out",
        str(out),
        path=fake_site,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    assert "engine drift: patched:Drift replaces the registered fakepkg:Drift in this run" in done.stderr
    rows = pd.read_csv(out / "results.csv").query("engine == 'drift'")
    assert len(rows) and (rows["error"] > 0.1).all()  # the patched class ran, not the exact one


def test_a_broken_registration_is_one_line_exit_2(tmp_path):
    site = tmp_path / "site"
    info = site / "broken-1.0.dist-info"
    info.mkdir(parents=True)
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: broken\nVersion: 1.0\n")
    (info / "entry_points.txt").write_text("[truestep.cases]\nbroken = no_such_module\n")
    done = _cli("list", path=site)
    assert done.returncode == 2 and "Traceback" not in done.stderr
    assert "entry point truestep.cases broken = 'no_such_module'" in done.stderr


def test_a_case_package_that_ships_no_case_files_says_how_to_ship_them(tmp_path):
    """A non-editable install without a package-data line leaves the case files behind:
    the registration names the empty folder and the pyproject line that ships them."""
    site = tmp_path / "site"
    (site / "emptycases").mkdir(parents=True)
    (site / "emptycases" / "__init__.py").write_text("")
    info = site / "emptycases-1.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: emptycases\nVersion: 1.0\n")
    (info / "entry_points.txt").write_text("[truestep.cases]\nmine = emptycases\n")
    done = _cli("list", path=site)
    assert done.returncode == 2 and "Traceback" not in done.stderr
    assert "holds no case files (*.toml)" in done.stderr
    assert '[tool.setuptools.package-data] emptycases = ["*.toml"]' in done.stderr
