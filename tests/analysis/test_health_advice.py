"""The health's advice names only settings and options that exist: every "[section] key" in the messages of
analysis/health.py (with health_counters.py and health_losses.py) and analysis/prior_check.py is a field of that
configuration section, every "--option" one of the command line's; the robust-kernel advice names a stronger
kernel than the one that is on, none when the strongest is on."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

import gtsam_dvl
from gtsam_dvl.analysis import health, health_counters, health_losses, prior_check
from gtsam_dvl.core.config import EstimatorConfig

PACKAGE = Path(gtsam_dvl.__file__).parent
# the health's messages are in health.py and the modules it is split into (counters, losses)
SOURCES = [Path(m.__file__) for m in (health, health_counters, health_losses, prior_check)]


def _messages(path: Path) -> str:
    """The string literals of a module (f-strings' text parts included), docstrings left out: its messages."""
    tree = ast.parse(path.read_text())
    docstrings = {
        id(node.body[0].value)
        for node in ast.walk(tree)
        if isinstance(node, (ast.Module, ast.FunctionDef, ast.ClassDef))
        and node.body
        and isinstance(node.body[0], ast.Expr)
        and isinstance(node.body[0].value, ast.Constant)
    }
    return "\n".join(
        node.value
        for node in ast.walk(tree)
        if isinstance(node, ast.Constant)
        and isinstance(node.value, str)
        and id(node) not in docstrings
    )


def _named(pattern: str) -> set[tuple[str, ...]]:
    found: set[tuple[str, ...]] = set()
    for path in SOURCES:
        found |= {m if isinstance(m, tuple) else (m,) for m in re.findall(pattern, _messages(path))}
    return found


def test_named_settings_exist() -> None:
    sections = set(EstimatorConfig.model_fields)
    settings = {(a, b) for a, b in _named(r"\[([a-z]+)\] ([a-z_]+)") if a in sections}
    assert ("dvl", "robust") in settings and ("priors", "misalignment_sigma_deg") in settings
    config = EstimatorConfig()
    for section, key in settings:
        assert key in type(getattr(config, section)).model_fields, f"[{section}] {key}"


def test_named_options_exist() -> None:
    options = {o for (o,) in _named(r"(--[a-z][a-z-]+)")}
    assert "--repair" in options
    cli = "".join(
        (PACKAGE / "app" / name).read_text()
        for name in ("cli.py", "cli_options.py", "cli_campaign.py")
    )
    for option in options:
        assert f'"{option}"' in cli, option


@pytest.mark.parametrize(
    ("robust", "named"), [("none", "huber"), ("huber", "cauchy"), ("cauchy", None)]
)
def test_kernel_advice_names_a_stronger_kernel(robust: str, named: str | None) -> None:
    advice = health._kernel_advice(robust)
    if named is None:
        assert advice == ""
    else:
        assert f'[dvl] robust = "{named}"' in advice and f'"{robust}"' not in advice
