#!/usr/bin/env bash
# Regenerates every picture of the README and the manual (docs/*.png): `make pictures`.
# Each line is the command a page names beside its picture; about 3 minutes on 2 cores.
set -euo pipefail
cd "$(dirname "$0")/.."
export PATH="$PWD/.venv/bin:$PATH" ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST AMENT_PREFIX_PATH="$PWD/.venv"
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT

# the demo's C-space slices (verify-and-slice.md, scenes.md)
cdh-planner demo --out "$out/demo" > /dev/null
cp "$out"/demo/robot1_slice.png "$out"/demo/robot2_sphere.png "$out"/demo/robot2_sphere_ball.png docs/
# atlases and paths (planning.md)
cdh-planner plan config/problems/robot1_qs_qg.yaml --strategy astar --quiet --plot docs/robot1_atlas_astar.png > /dev/null
cdh-planner plan config/problems/robot1_qs_qg.yaml --strategy gbf --quiet --plot docs/robot1_atlas_gbf.png > /dev/null
cdh-planner plan config/problems/robot2_q2_q3.yaml --strategy astar --quiet --plot docs/robot2_atlas.png > /dev/null
mv docs/robot2_atlas_tensions.png docs/robot2_tensions.png
rm -f docs/robot1_atlas_astar_tensions.png docs/robot1_atlas_gbf_tensions.png
# studies (performance.md, more-cables.md)
python benchmarks/dynamics.py --picture docs/robot2_dynamics.png > /dev/null
python benchmarks/clearance.py --picture docs/clearance.png > /dev/null
cdh-planner slice config/cogiro.yaml --fixed z=2.5 phi=0 theta=0 sigma=0 --free x y \
    --range x=-7.5:7.5 y=-5.5:5.5 --resolution 300 -o docs/cogiro_slice.png > /dev/null
echo "pictures: $(ls docs/*.png | wc -l) in docs/"
