"""Pictures of a collider asset (the ``render`` extra: pyvista/VTK, matplotlib, Pillow), one floor
above the validators: :mod:`.draw` holds the one offscreen set-up and draws an asset, its part
spheres and a player run (``colossus render``, ``colossus play``); :mod:`.html` is the HTML report
with its pictures (``colossus validate --format html``)."""
