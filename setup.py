"""Packaging for cf_estimator: an ament_python ROS 2 package that is also a plain pip package.

``colcon build`` installs the console scripts into ``lib/cf_estimator`` (see setup.cfg) so
``ros2 run cf_estimator cf_estimator_node`` finds them; ``pip install .`` puts them on PATH.
``ext_modules``: the optional compiled filter step (the C core cf_estimator/core/c/cf_core.c
and its binding cf_estimator/core/_kernel.c).
The ``data_files`` below are what colcon (and pip) install under ``share/cf_estimator``:
the ament index marker, package.xml, the launch files and the parameter YAML.
"""

import os
from glob import glob
from pathlib import Path

from setuptools import Extension, find_namespace_packages, setup
from setuptools.command.build_ext import build_ext

PACKAGE = "cf_estimator"
#: The node's ROS 2 runtime as PyPI wheels (extra "ros"; scripts/test.sh installs it when rclpy
#: is not importable). rcl_interfaces, rosgraph_msgs, builtin_interfaces... come along.
ROS_WHEELS = (
    "ros-jazzy-rclpy", "ros-jazzy-sensor-msgs", "ros-jazzy-geometry-msgs",
    "ros-jazzy-diagnostic-msgs", "ros-jazzy-rmw-fastrtps-cpp", "ros-jazzy-nav-msgs",
)
ROS_WHEEL_MARKER = (
    'sys_platform == "linux" and platform_machine == "x86_64" and '
    'platform_python_implementation == "CPython" and python_version < "3.14"'
)
#: ``CF_ESTIMATOR_NO_EXTENSION=1 pip install .`` (or colcon build): no compiled step, the Python
#: reference runs everything (what a machine without a C compiler gets).
NO_EXTENSION_ENV = "CF_ESTIMATOR_NO_EXTENSION"


class BuildKernel(build_ext):
    """The optional C twin of the filter step, built fresh every time or not at all.

    An earlier build's ``_kernel*.so`` (in ``build/`` or in place) is removed first, so the
    result always reflects this build: ``$CF_ESTIMATOR_NO_EXTENSION`` set to 1/true/yes skips the
    extension, and a compiler that fails (``CC=/bin/false``, or none installed) gives the
    pure-Python install instead of silently reusing a stale binary.
    """

    def run(self) -> None:
        for ext in self.extensions:
            for stale in {Path(self.get_ext_fullpath(ext.name)),
                          Path(self.get_ext_fullpath(ext.name)).resolve()}:
                stale.unlink(missing_ok=True)
        if os.environ.get(NO_EXTENSION_ENV, "").strip().lower() in ("1", "true", "yes"):
            print(f"{NO_EXTENSION_ENV} is set: not building the compiled filter step "
                  "(the Python reference runs)")
            return
        super().run()


setup(
    name=PACKAGE,
    version="0.1.0",  # keep equal to package.xml (test/test_packaging.py checks it)
    description="Complementary-filter attitude estimation for ROS 2: node, bag replay, tuning.",
    license="Apache-2.0",
    python_requires=">=3.11",
    # Namespace discovery so a sub-package is never silently dropped for a missing __init__.py.
    packages=find_namespace_packages(
        include=[PACKAGE, f"{PACKAGE}.*"], exclude=["*.__pycache__", "*.__pycache__.*"]
    ),
    # The compiled twin of core/step.py (see core/kernel.py). optional=True: without a C compiler
    # (or with $CF_ESTIMATOR_NO_EXTENSION=1, see BuildKernel) the build goes on and the Python
    # reference runs everything, only slower.
    cmdclass={"build_ext": BuildKernel},
    # the standalone C core travels with the package (sdist and wheel): a C/C++ user compiles
    # cf_core.c beside cf_core.h (docs/ARCHITECTURE.md "The core in C")
    package_data={f"{PACKAGE}.core.c": ["cf_core.h", "cf_core.c"]},
    ext_modules=[
        Extension(
            f"{PACKAGE}.core._kernel",
            # the standalone C core (plain C99, no Python.h) and its Python binding
            [f"{PACKAGE}/core/c/cf_core.c", f"{PACKAGE}/core/_kernel.c"],
            include_dirs=[f"{PACKAGE}/core/c"],
            depends=[f"{PACKAGE}/core/c/cf_core.h"],
            # no FMA (-ffp-contract=off): the same bits as Python; -O3 and -fno-math-errno
            # (sqrt inline: no errno to set) change the instructions, not the results
            extra_compile_args=["-O3", "-fno-math-errno", "-ffp-contract=off"],
            optional=True,
        )
    ],
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
        (f"share/{PACKAGE}/launch", sorted(glob("launch_scripts/*.launch.py"))),
        (f"share/{PACKAGE}/config", sorted(glob("config/*.yaml"))),
    ],
    install_requires=[
        "numpy",
        "scipy",
        # the range bag/io.py is tested with (ROSBAGS_TESTED: its direct mcap path writes into
        # rosbags' McapWriter; 0.10 lacks the public StoragePlugin)
        "rosbags>=0.11,<0.12",
        # truncated mcap bags read forward without their summary (bag/salvage.py): its
        # StreamReader; lz4 (a rosbags dependency too) for the chunk a cut bag ends in
        "mcap>=1.1,<2",
        "lz4",
        "matplotlib",
        "h5py",
        "tqdm",
        "pyyaml",
        # PX4 .ulg flight logs for the offline tools (replay, tune --bag); never the node's
        "pyulog",
        # ArduPilot .bin DataFlash logs (DFReader) for the offline tools; never the node's
        "pymavlink",
    ],
    extras_require={
        # vqf, imufusion: the peers the bench tests run (test_fair_peers.py: Fusion's recommended
        # set-up at work); dask[distributed]: the LocalCluster (loopback) tests;
        # pytest-timeout: a hung test fails after 10 minutes (pyproject: timeout), not at CI's
        # limit;
        # pytest-xdist: scripts/test.sh runs the suite on every core (-n auto)
        "test": ["pytest", "pytest-timeout", "pytest-xdist", "hypothesis", "ruff", "vqf",
                 "imufusion", "dask[distributed]"],
        # --cluster ADDRESS|local:N on replay, tune and bench (docs/cluster.md)
        "cluster": ["dask[distributed]"],
        # riann: RIANN on ONNX Runtime (~80 MB installed, no torch); its weights ship inside
        "bench": ["vqf", "imufusion", "ahrs", "riann"],
        # ROS 2 Jazzy's rclpy and messages from PyPI, for running the node without a ROS install
        # (x86_64 Linux, CPython 3.10-3.13). On a ROS install rclpy comes from apt: not this.
        "ros": [f"{wheel}; {ROS_WHEEL_MARKER}" for wheel in ROS_WHEELS],
    },
    entry_points={
        "console_scripts": [
            "cf-estimator = cf_estimator.cli.main:main",
            "cf_estimator_node = cf_estimator.node.cf_estimator_node:main",
        ],
    },
)
