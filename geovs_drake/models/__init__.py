"""Robot models shipped with the package (found with importlib.resources): ``ur5.urdf``, a
6-axis arm with the UR5's published parameters (its header says where each number comes
from)."""
