"""The `puppet` command. Each subcommand lives in its own module with `register(subparsers)`;
heavy imports happen inside the command so `puppet --help` stays fast."""

from __future__ import annotations

import argparse
import importlib
import re
import signal
import sys

from devices.errors import DeviceError
from puppet.errors import PuppetError
from safefile import BadFile

# Subcommand modules, in help order, with the commands each registers. Each defines
# register(subparsers) -> None and sets `func(args) -> int` on its parser with set_defaults.
COMMANDS = (
    ("puppet.cmd_live", ("live",)),
    ("puppet.cmd_pose", ("pose",)),
    ("puppet.cmd_view", ("view",)),
    ("puppet.cmd_channels", ("channels",)),
    ("puppet.cmd_devices", ("devices", "monitor")),
    ("puppet.cmd_learn", ("learn",)),
    ("puppet.cmd_replay", ("replay",)),
    ("puppet.cmd_edit", ("edit",)),
    ("puppet.cmd_import_face", ("import-face",)),
    ("puppet.cmd_face", ("face",)),
    ("puppet.cmd_fit", ("fit",)),
    ("puppet.cmd_recognize", ("recognize",)),
    ("puppet.cmd_templates", ("templates",)),
    ("puppet.cmd_takes", ("takes",)),
    ("puppet.cmd_batch", ("batch",)),
)
COMMAND_MODULES = tuple(module for module, _ in COMMANDS)


def build_parser(argv: list[str] | None = None) -> argparse.ArgumentParser:
    """The `puppet` parser. Given the arguments, and their first word names a command, only that
    command's module is imported and registered (all of them took 70-116 ms of CPU, one 45-59 ms,
    at load 8: of every start, a batch client's among them); otherwise, as for `puppet --help`,
    all of them."""
    parser = argparse.ArgumentParser(
        prog="puppet",
        description="Real-time facial puppetry: control boxes drive a physically-based face.",
    )
    from puppet import __version__

    parser.add_argument("--version", action="version", version=f"puppet {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    first = argv[0] if argv else None
    named = [module for module, names in COMMANDS if first in names]
    for name in named or COMMAND_MODULES:
        try:
            module = importlib.import_module(name)
        except ModuleNotFoundError as err:
            if err.name == name:  # command not built yet in this checkout
                continue
            raise
        module.register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    try:  # Ctrl-C while the command's modules are imported (the first 0.1-0.3 s) was a traceback
        parser = build_parser(sys.argv[1:] if argv is None else argv)
        args = parser.parse_args(argv)
    except KeyboardInterrupt:
        return 130
    if not getattr(args, "func", None):
        parser.print_help()
        return 0
    if argv is None and args.command not in OWN_SIGNALS:
        terminate_as_interrupt()
    try:
        if getattr(args, "rig", None) and getattr(args, "face", None) is not None:
            # both name the face: the rig won without a word (live, pose, view, fit, replay)
            raise PuppetError(f"--rig {args.rig} and --face {args.face} each name the face: give one of them")
        code = int(args.func(args) or 0)
    except (PuppetError, DeviceError, BadFile) as err:
        print(f"puppet: error: {short_words(str(err))}", file=sys.stderr)
        code = 2
    except Terminated:
        return 128 + signal.SIGTERM
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError:  # the reader stopped early (`puppet takes list | head`): not an error to report
        import os

        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # the exit's flush writes nowhere
        return 141
    if argv is None and getattr(args, "exit_at_once", False):
        exit_at_once(code)
    return code


#: commands that handle SIGINT and SIGTERM themselves (a show closes its recording)
OWN_SIGNALS = ("live", "edit")


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised where Ctrl-C's KeyboardInterrupt is: the command unwinds as on Ctrl-C."""


def terminate_as_interrupt() -> None:
    """SIGTERM (`kill`, a service manager, a batch system's time limit) ends a command the way
    Ctrl-C does: its temporary files are removed and the files it was replacing stay as they
    were. Python's default for SIGTERM ends the process at once, leaving a hidden `.NAME.*.part`
    file beside every output it was writing."""

    def handler(signum: int, frame: object) -> None:
        raise Terminated

    try:
        signal.signal(signal.SIGTERM, handler)
    except ValueError:  # not the main thread
        pass


def short_words(message: str, longest: int = 300) -> str:
    """The error line with any word longer than `longest` characters (a pasted path or value of
    thousands) shown by its start and end, so the line stays short and still names the thing."""
    return re.sub(r"\S{%d,}" % (longest + 1), lambda m: f"{m.group()[:120]}...{m.group()[-60:]}", message)


def exit_at_once(code: int) -> None:
    """End this process now, without the interpreter's teardown: for a command that has closed
    everything it wrote and imported much (`puppet batch`: Dask, numpy, the simulator), taking the
    ~700 modules apart one by one costs a tenth of a second or more after the work is done.
    Only for the command line (`main` with no argv): a caller in-process gets its return."""
    import logging
    import os

    logging.shutdown()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):
            pass
    os._exit(code)


if __name__ == "__main__":
    sys.exit(main())
