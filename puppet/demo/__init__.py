"""The built-in demo: a scripted performance (`demo.toml`, a mock:// script that plays the SGI
dial-and-button box) shown by `puppet live --demo`, and by `puppet live` when there is neither a
control box nor a display."""

from pathlib import Path

SCRIPT = Path(__file__).with_name("demo.toml")
