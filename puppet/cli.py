"""The `puppet` command. Each subcommand lives in its own module with `register(subparsers)`;
heavy imports happen inside the command so `puppet --help` stays fast."""

from __future__ import annotations

import argparse
import importlib
import sys

from devices.errors import DeviceError
from puppet.errors import PuppetError
from safefile import BadFile

# Subcommand modules, in help order. Each defines register(subparsers) -> None and sets
# `func(args) -> int` on its parser with set_defaults.
COMMAND_MODULES = (
    "puppet.cmd_live",
    "puppet.cmd_pose",
    "puppet.cmd_view",
    "puppet.cmd_channels",
    "puppet.cmd_devices",
    "puppet.cmd_learn",
    "puppet.cmd_replay",
    "puppet.cmd_edit",
    "puppet.cmd_import_face",
    "puppet.cmd_face",
    "puppet.cmd_fit",
    "puppet.cmd_recognize",
    "puppet.cmd_templates",
    "puppet.cmd_takes",
    "puppet.cmd_batch",
)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="puppet",
        description="Real-time facial puppetry: control boxes drive a physically-based face.",
    )
    from puppet import __version__

    parser.add_argument("--version", action="version", version=f"puppet {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMAND_MODULES:
        try:
            module = importlib.import_module(name)
        except ModuleNotFoundError as err:
            if err.name == name:  # command not built yet in this checkout
                continue
            raise
        module.register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 0
    try:
        return int(args.func(args) or 0)
    except (PuppetError, DeviceError, BadFile) as err:
        print(f"puppet: error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
