"""The puppet application: channels, mapping, the live loop, recording, replay, export, the CLI."""

__version__ = "0.1.0"
