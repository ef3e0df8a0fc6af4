"""The project's error hierarchy: one base class, device errors under it."""

from __future__ import annotations


class PuppetError(Exception):
    """Base of every error the program reports to the user as one clear line."""


class ConfigError(PuppetError):
    """A file the user gave us (mapping, rig, recording, curves) is wrong: message names file:line."""


class ChannelError(PuppetError, ValueError):
    """An unknown channel, AU or expression, or a value out of range."""
