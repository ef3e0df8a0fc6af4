"""The project's error hierarchy: one base class, device errors under it."""

from __future__ import annotations


class PuppetError(Exception):
    """Base of every error the program reports to the user as one clear line."""


class ConfigError(PuppetError):
    """A file the user gave us (mapping, rig, recording, curves) is wrong: message names file:line."""


class ChannelError(PuppetError, ValueError):
    """An unknown channel, AU or expression, or a value out of range."""


def not_applying(options: "list[str]", what: str) -> str:
    """The one line said (after the result) for options given that do nothing for `what`, '' if none:
    `puppet: note: --view and --size do not apply to a .csv of channels; ignored`."""
    if not options:
        return ""
    return f"puppet: note: {' and '.join(options)} {'does' if len(options) == 1 else 'do'} not apply to {what}; ignored"
