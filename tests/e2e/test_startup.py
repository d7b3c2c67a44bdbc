"""Start-up of the command line: ``gcs-utm --help`` imports no heavy module, and a command
imports only what it uses (issue 24); the list of commands shown without importing them is
the list the modules register."""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

from gcs_utm.cli import COMMANDS, build_parser

ROOT = Path(__file__).resolve().parents[2]
HEAVY = ("numpy", "pymavlink", "textual", "matplotlib", "shapely", "gcs_utm.app")


def _imported_after(argv: list[str]) -> set[str]:
    """Which of HEAVY a fresh interpreter has imported after ``gcs-utm ARGV``."""
    code = (
        "import sys\n"
        "from gcs_utm.cli import main\n"
        "try:\n"
        f"    main({argv!r})\n"
        "except SystemExit:\n"
        "    pass\n"
        f"print('IMPORTED', *(m for m in {HEAVY!r} if m in sys.modules))\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT
    )
    (last,) = (line for line in out.stdout.splitlines() if line.startswith("IMPORTED"))
    return set(last.split()[1:])


def _helps(parser: argparse.ArgumentParser) -> dict[str, str | None]:
    (sub,) = (a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return {a.dest: a.help for a in sub._choices_actions}


def test_help_imports_nothing_heavy() -> None:
    assert _imported_after(["--help"]) == set()
    assert _imported_after([]) == set()


def test_scenario_check_imports_no_app_ui_or_mavlink() -> None:
    found = _imported_after(["scenario", "check", str(ROOT / "config/scenarios/use_case_1.toml")])
    assert "numpy" in found  # it does check the plans
    assert not found & {"pymavlink", "textual", "matplotlib", "gcs_utm.app"}


def test_the_command_list_is_what_the_modules_register() -> None:
    full = _helps(build_parser())
    assert full == {name: help_text for name, (_, help_text) in COMMANDS.items()}
    for name in COMMANDS:
        # a command's own parser is complete, the others are listed with the same help
        assert _helps(build_parser(name)) == full
        assert set(build_parser(name)._subparsers._group_actions[0].choices) == set(COMMANDS)  # type: ignore[union-attr]
