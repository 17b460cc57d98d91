"""Studies over many poses and designs (README, "workspace and sweep"): workspace analysis, reachability maps and
design sweeps. The core (``workspace``, ``sweep``) is plain Python and numpy; it runs calls on
an executor (``executors``): in this process, or on Ray actors (Ray is imported only there)."""
