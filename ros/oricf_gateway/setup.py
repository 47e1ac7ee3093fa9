"""The ORICF gateway as an ament_python package: what `colcon build` installs.

- share/ament_index/resource_index/packages/oricf_gateway: the marker that makes the package
  known to `ros2 run`, `ros2 launch` and ament_index;
- share/oricf_gateway/package.xml and launch/*.launch.py;
- lib/oricf_gateway/gateway (setup.cfg): the node, oricf.gateway.shells.main:ros_main.

No Python code of its own: the gateway is the `oricf` package, installed by pip into the
Python that runs colcon (docs/ros.md), whose path the executable's first line names.
"""

from glob import glob

from setuptools import setup

PACKAGE = "oricf_gateway"

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=[],
    py_modules=[],
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
        (f"share/{PACKAGE}/launch", sorted(glob("launch/*.launch.py"))),
    ],
    zip_safe=True,
    maintainer="ORICF maintainers",
    description="The ORICF gateway node: ROS 2 topics to AI model services and back",
    license="Apache-2.0",
    entry_points={"console_scripts": ["gateway = oricf.gateway.shells.main:ros_main"]},
)
