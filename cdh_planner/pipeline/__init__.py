"""The planning pipeline as stages, composed by ``planner.Planner``:

    lift      pose -> point of the navigation manifold M, or why not       (lift.py)
    route     the direct motion, else the atlas search (search.run)      (route.py)
    densify   waypoints until the motion between them is dense-feasible  (densify.py)
    smooth    Laplacian, or down the clearance cost                      (smooth.py)
    time      cable-space timing, checked as a controller executes it    (timing.py)

Every stage asks one ``validity.Validity`` whether a pose or a motion is allowed, so new
checks (collisions, cable interference) plug in at one place. ``metrics``: the task's
path costs. Stages work in task coordinates y (N, k) rows (``model.task``).
"""
