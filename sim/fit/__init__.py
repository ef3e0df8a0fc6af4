"""Analysis by synthesis (seed 000, section 6): from skin motion back to the channels that explain
it, and from skin motion to the expression it shows.

- `sim.fit.basis`: the displacement basis and the expression templates, built by settling the
  simulator (never hard-coded), and the settled displacement of any control values.
- `sim.fit.align`: Procrustes (similarity and rigid) between point sets.
- `sim.fit.solve`: the per-frame bounded fit, smoothed over time and re-linearised where the
  channels interact, with a per-frame report.
- `sim.fit.recognize`: expression scores from displacement templates and from activations, and
  the time spans they give.

Knows nothing of files or commands (the readers and `puppet fit` / `puppet recognize` are in
`puppet/`). Units: cm, like the rest of `sim`.
"""
