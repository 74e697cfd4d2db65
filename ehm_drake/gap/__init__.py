"""The sim-to-real gap diagnosis: where a body's measured transmissibility
departs from the model, which unmodelled effect explains it, and how far
the gap shrinks with it (user guide: docs/guide.md, "The gap diagnosis").

Rooms, in the order the method uses them:

- `library`: the candidate effects (each a model extension), the model's
  linear families (base parameters, effect grids) and the candidate models
  fitted to measured tests.
- `single`: one subject -- the ordinary pass (`diagnose`: cells, ranking,
  `verdict`) and the structural pass (`discrepancy`: a smooth model-form
  gap, shared by the levels, against which a level-dependent effect must
  stand out).
- `reference_group`: against a group of subjects measured with the same
  protocol -- the group's scatter, the anchor, the calibrated thresholds,
  the contrast measurements.
- `lab`: simulated laboratories -- synthetic data with hidden effects
  (`synth`, as C3D sessions: `synth_c3d`) and the blind check (`blind`).
- `report` writes a diagnosis; `commands` are the CLI's ``diagnose``,
  ``synth`` and ``blind``.
"""
