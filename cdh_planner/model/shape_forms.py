"""The compiled collision kernel's form codes of a platform shape (scene/kernels.py: _own,
_sdf, _segment_sdf), shared by the kernel and the shape classes (model/shapes.py:
``kernel_form``). Part of the kernel's source digest: a change rebuilds it."""

SPHERE_FORM = 0.0    # radius
BOX_FORM = 1.0       # half edges
CYLINDER_FORM = 2.0  # radius, half height (axis z)
COAL_FORM = 3.0      # left to coal: a mesh, or no platform
CAPSULE_FORM = 4.0   # radius, half length of its segment (axis z)
