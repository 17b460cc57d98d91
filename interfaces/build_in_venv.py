"""Build the ROS 2 interface packages of interfaces/ into a venv holding ROS 2 Jazzy from PyPI.

    .venv/bin/python interfaces/build_in_venv.py [--build-dir build/interfaces] [--jobs N]

Run it with the venv's own python, after ``pip install -r requirements.txt`` (``make venv``
does both). Installs into that venv (``sys.prefix``):

1. Patches the ``*_rosidl_generator_pyExport.cmake`` files that the message wheels ship:
   they name the include folders of the Python the wheels were built with
   (``/opt/python/cp311-cp311/...``); they get this venv's Python and numpy include
   folders instead. Idempotent; needed again after any reinstall of those wheels.
2. Builds each package with plain CMake (``cmake -S interfaces/<pkg> -B <build-dir>/<pkg>``,
   install prefix the venv) and installs it:
   - ``cdh_planner_interfaces`` always;
   - ``control_msgs`` (a partial copy: FollowJointTrajectory) and ``tf2_msgs`` (a partial
     copy: TFMessage) each only when this python cannot import the real package from
     outside the venv.

Afterwards ``AMENT_PREFIX_PATH=<venv>`` is all the generated types need at run time. Each
package's CMake output goes to ``<build-dir>/<pkg>.log``; its tail is printed on failure.
Exit code 0 when everything is built, 1 otherwise (with the reason on stderr).
"""

import argparse
import importlib.util
import os
import re
import shutil
import subprocess
import sys
import sysconfig
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
PACKAGES = ("cdh_planner_interfaces", "control_msgs", "tf2_msgs")
COPIES = ("control_msgs", "tf2_msgs")   # partial copies: built only without the real one
# an include folder of another Python (python3.X) or of another numpy, in an
# INTERFACE_INCLUDE_DIRECTORIES list
PYTHON_INCLUDE = re.compile(r'(?<=[";])/[^";]*/include/python3\.\d+(?=[";])')
NUMPY_INCLUDE = re.compile(r'(?<=[";])/[^";]*/numpy/(?:_core|core)/include(?=[";])')


def python_include():
    return sysconfig.get_paths()["include"]


def patch_export_files(prefix):
    """Rewrite the foreign Python and numpy include folders in ``prefix``'s
    ``*_rosidl_generator_pyExport.cmake`` files to this interpreter's. The files changed."""
    import numpy
    py_inc, np_inc = python_include(), numpy.get_include()
    changed = []
    for f in sorted(Path(prefix, "share").glob("*/cmake/*_rosidl_generator_pyExport.cmake")):
        text = f.read_text()
        new = NUMPY_INCLUDE.sub(lambda m: np_inc, PYTHON_INCLUDE.sub(lambda m: py_inc, text))
        if new != text:
            f.write_text(new)
            changed.append(f)
    return changed


def real_package(name, prefix):
    """The folder of a package ``name`` this python imports from outside ``prefix`` (a real
    ROS install), or None (none, or only the copy built into ``prefix``)."""
    saved = sys.path[:]
    # not interfaces/<name> itself (the script's folder is first on sys.path)
    sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != HERE]
    try:
        spec = importlib.util.find_spec(name)
    finally:
        sys.path[:] = saved
    if spec is None or spec.origin is None:   # none, or a folder without __init__.py
        return None
    where = Path(spec.origin).resolve().parent
    return None if where.is_relative_to(Path(prefix).resolve()) else where


def build(package, prefix, build_dir, jobs):
    """Configure, build and install ``interfaces/<package>`` into ``prefix``; the log file.
    RuntimeError with the log's tail if a step fails."""
    src, out = HERE / package, Path(build_dir) / package
    log = Path(build_dir) / f"{package}.log"
    out.mkdir(parents=True, exist_ok=True)
    env = dict(os.environ, AMENT_PREFIX_PATH=str(prefix), CMAKE_PREFIX_PATH=str(prefix))
    steps = [
        ["cmake", "-S", str(src), "-B", str(out), f"-DCMAKE_INSTALL_PREFIX={prefix}",
         f"-DCMAKE_PREFIX_PATH={prefix}", f"-DPython3_EXECUTABLE={sys.executable}",
         "-DBUILD_TESTING=OFF"],
        ["cmake", "--build", str(out), "--parallel", str(jobs)],
        ["cmake", "--install", str(out)],
    ]
    with open(log, "w") as f:
        for cmd in steps:
            f.write("$ " + " ".join(cmd) + "\n")
            f.flush()
            rc = subprocess.run(cmd, stdout=f, stderr=subprocess.STDOUT, env=env).returncode
            if rc != 0:
                f.close()
                tail = "".join(log.read_text().splitlines(True)[-40:])
                raise RuntimeError(f"{package}: `{' '.join(cmd[:3])} ...` failed (exit {rc}); "
                                   f"the end of {log}:\n{tail}")
    return log


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--build-dir", default="build/interfaces",
                    help="CMake build folders and logs (default: build/interfaces)")
    ap.add_argument("--jobs", type=int, default=os.cpu_count() or 1)
    args = ap.parse_args(argv)
    prefix = Path(sys.prefix)
    if prefix == Path(sys.base_prefix):
        print("build_in_venv.py: run it with the venv's python (.venv/bin/python)", file=sys.stderr)
        return 1
    for tool in ("cmake", "make", "cc", "c++"):
        if shutil.which(tool) is None:
            print(f"build_in_venv.py: `{tool}` not found: the interfaces need cmake, make, gcc "
                  f"and g++ (Debian: apt-get install cmake make gcc g++)", file=sys.stderr)
            return 1
    if not Path(python_include(), "Python.h").exists():
        v = f"{sys.version_info.major}.{sys.version_info.minor}"
        print(f"build_in_venv.py: Python.h not found in {python_include()} "
              f"(Debian: apt-get install python{v}-dev)", file=sys.stderr)
        return 1

    changed = patch_export_files(prefix)
    print(f"interfaces: include folders patched in {len(changed)} "
          f"*_rosidl_generator_pyExport.cmake files")
    for package in PACKAGES:
        if package in COPIES and (real := real_package(package, prefix)) is not None:
            print(f"interfaces: {package} not built: the real one is at {real}")
            continue
        t0 = time.monotonic()
        try:
            log = build(package, prefix, args.build_dir, args.jobs)
        except RuntimeError as e:
            print(f"build_in_venv.py: {e}", file=sys.stderr)
            return 1
        print(f"interfaces: {package} built and installed into {prefix} in "
              f"{time.monotonic() - t0:.0f} s (log: {log})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
