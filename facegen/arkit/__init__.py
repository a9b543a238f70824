"""Apple ARKit's 52 face blend shapes on facegen's face: their names (`names`), the 52 shapes as deformations
of the procedural face (`shapes`), and the solver that turns any animation of that face into per-frame shape
weights (`solve`). The exchange formats that carry the weights (Audio2Face JSON, Live Link Face CSV, `--rig
arkit` glTF/USD) read them from here."""
