#!/usr/bin/env bash
# Regenerates every picture of the README and the manual (docs/*.png): `make pictures`.
# Each line is the command a page names beside its picture; about 3 minutes on 2 cores.
set -euo pipefail
cd "$(dirname "$0")/.."
export PATH="$PWD/.venv/bin:$PATH" ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST AMENT_PREFIX_PATH="$PWD/.venv"
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
# run CMD...: quietly; on a failure its output's tail and the command, then stop
run() {
    if ! "$@" > "$out/log" 2>&1; then
        tail -20 "$out/log" >&2; echo "pictures: failed: $*" >&2; exit 1
    fi
}

# the demo's C-space slices (verify-and-slice.md, scenes.md)
run cdh-planner demo --out "$out/demo"
cp "$out"/demo/robot1_slice.png "$out"/demo/robot2_sphere.png "$out"/demo/robot2_sphere_ball.png docs/
# atlases and paths (planning.md)
run cdh-planner plan config/problems/robot1_qs_qg.yaml --strategy astar --quiet --plot docs/robot1_atlas_astar.png
run cdh-planner plan config/problems/robot1_qs_qg.yaml --strategy gbf --quiet --plot docs/robot1_atlas_gbf.png
run cdh-planner plan config/problems/robot2_q2_q3.yaml --strategy astar --quiet --plot docs/robot2_atlas.png
mv docs/robot2_atlas_tensions.png docs/robot2_tensions.png
rm -f docs/robot1_atlas_astar_tensions.png docs/robot1_atlas_gbf_tensions.png
# studies (performance.md, more-cables.md)
run python benchmarks/dynamics.py --picture docs/robot2_dynamics.png
run python benchmarks/clearance.py --picture docs/clearance.png
run cdh-planner slice config/cogiro.yaml --fixed z=2.5 phi=0 theta=0 sigma=0 --free x y \
    --range x=-7.5:7.5 y=-5.5:5.5 --resolution 300 -o docs/cogiro_slice.png
echo "pictures: $(ls docs/*.png | wc -l) in docs/"
