"""Obstacles and cable interference: the scene (``schema``: what a scene file
holds, read and checked in one place) and its collision checks (``collision``: cables as
capsules, the platform's shape and the obstacles, distances by the coal library)."""
