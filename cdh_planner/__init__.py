"""cdh_planner: wrench-feasible path planning for cable-driven hexapods.

After Bohigas, Manubens & Ros, "Computing wrench-feasible paths for cable-driven
hexapods". SI units at every edge (metres, newtons, radians).
"""

__version__ = "0.1.0"
