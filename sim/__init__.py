"""The face: rig building, skin springs, muscles, wrinkles, integrator. Knows nothing of devices
or OpenGL."""
