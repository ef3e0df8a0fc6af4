"""Exports of a performance: point cache (PC2 + OBJ), channel and ARKit CSVs, video, frames."""
