"""One user-error type: ``userio.errors.InputError``, imported from there by every module (no
``<package>/errors.py`` re-export shims); the bridge's named warnings live where they are raised."""

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("bridge", "flexure", "calibration", "estimator", "torquebench", "userio")


def _sources():
    for pkg in PACKAGES:
        yield from sorted((ROOT / pkg).rglob("*.py"))
    yield from sorted((ROOT / "tests").glob("*.py"))
    yield from sorted((ROOT / "benchmarks").rglob("*.py"))


def test_no_package_but_userio_has_an_errors_module():
    shims = [str(p.relative_to(ROOT)) for pkg in PACKAGES if pkg != "userio"
             for p in (ROOT / pkg).rglob("errors.py")]
    assert shims == []


def test_input_error_is_imported_from_userio_only():
    wrong = []
    for path in _sources():
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom) and node.module and node.module != "userio.errors":
                if node.module.endswith(".errors") or any(a.name == "InputError" for a in node.names):
                    wrong.append(f"{path.relative_to(ROOT)}:{node.lineno} from {node.module}")
    assert wrong == []


def test_the_bridge_warnings_are_one_family_raised_where_declared():
    from bridge.chain import ADCSaturationWarning
    from bridge.wheatstone import BridgeInverseWarning, BridgeWarning, StrainRangeWarning

    for w in (ADCSaturationWarning, BridgeInverseWarning, StrainRangeWarning):
        assert issubclass(w, BridgeWarning) and issubclass(w, UserWarning)


def test_the_cli_maps_the_one_input_error_to_exit_2():
    from torquebench.cli import USER_ERRORS
    from userio.errors import InputError

    assert InputError in USER_ERRORS
