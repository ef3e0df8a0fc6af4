"""Batch work on Dask distributed: export, fit or recognize many takes at once, on this machine's
cores or on a farm of `dask worker`s (see docs/studio.md). `plan` decides what to do, `jobs` is
what workers run (the single commands' own functions), `run` is the client."""
