"""The face: core code every layer above builds on (arkit, exchange, datasets, lipsync, synth).

- `mesh`: the fixed-topology triangle Mesh, PLY/OBJ and region files, topology fingerprint, area, normals;
- `regions`: the region names in one place (lips, upper_face, the community's lve/fdd files, the sets the
  rig, the ARKit shapes and the lip-sync metrics need);
- `anatomy` and `procedural`: the procedural neutral face (BIWI's 23,370 vertices) and its speakers;
- `template`: the committed neutral face, shipped as package data in templates/ (`load_template`);
- `rig`: the motion rig that poses the face from channel weights.

Nothing here imports facegen.synth (synthetic data builds on the face, not the other way round).
"""
