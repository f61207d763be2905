"""The repository's root: the folder that holds tracer/, presets/, hud_addon/, tools/ and tests/."""

from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
